//! The shared context of the diagnosis' phases: the records prepared once (measured quantities,
//! fit and score samples, bootstrap units, each record's noise floor), the one residual iterator
//! every phase uses, per-channel and per-unit scores, and the noise floor.
//!
//! Noise floor (issue 17): from the differences of consecutive residuals, E[Δr²] = 2σ² for white
//! noise (smooth model errors cancel; sensor noise and the noise of measured inputs propagated
//! through the model — position noise into the torque, say — do not). The largest 2 % of the
//! squared differences (transients) are trimmed and the trimmed mean is divided by its Gaussian
//! consistency factor, so the floor is unbiased for Gaussian noise (the untrimmed-corrected
//! estimate was 9 % low and made every clean record look significant).

use crate::gap::eval::predict::{self, Predictions, Samples};
use crate::gap::eval::set_hooks::SetHooks;
use crate::gap::model::candidate::{Channel, Model};
use crate::gap::quality::{Facts, Profile};
use crate::gap::record::measured::Measured;
use crate::model::params::Params;
use crate::records::dataset::Dataset;
use crate::records::events::SegmentOptions;

/// E[X² | X² below its 98 % quantile] for a standard normal X: the consistency factor of the
/// 2 %-trimmed mean of squared differences.
pub const TRIM_CONSISTENCY: f64 = 0.873_466;

/// One record prepared for the diagnosis.
pub struct File {
    pub m: Measured,
    /// Samples for fitting (thinned).
    pub fit: Samples,
    /// Samples for scoring (all).
    pub all: Samples,
    /// Global block offset (bootstrap units).
    pub unit0: usize,
    /// Noise floor σ per channel of this record.
    pub sigma: Vec<f64>,
    /// Disk temperature estimate of the current base model (reused by torque fits).
    pub disk: Option<[Vec<f64>; 2]>,
    /// Per channel: how many samples each reading is held for, and the step of the grid its
    /// readings lie on (the data-quality stage's [`Facts`]; bounds of the noise floor).
    pub held: Vec<Option<usize>>,
    pub grid: Vec<Option<f64>>,
}

/// Prepares records: measured quantities, samples (fits thinned to at most `max_fit` samples
/// per channel group), bootstrap units. With `carry_energy`, the friction energy accumulates
/// over the records in order, starting at the given energies (J). `profiles` (one per record,
/// of the record as logged) say which samples are compared ([`compared`]).
#[allow(clippy::too_many_arguments)]
pub fn prepare(
    ds: &[Dataset],
    profiles: &[Profile],
    p: &Params,
    seg: &SegmentOptions,
    carry_energy: Option<[f64; 2]>,
    torque_stride: usize,
    temp_stride: usize,
    max_fit: usize,
) -> Vec<File> {
    let ms = if let Some(e0) = carry_energy {
        Measured::sequence_from(ds, p, seg, e0)
    } else {
        ds.iter()
            .map(|d| Measured::new(d, p, [0.0; 2], seg))
            .collect()
    };
    let total_torque: usize = ms
        .iter()
        .map(|m| m.torque_idx[0].len() + m.torque_idx[1].len())
        .sum();
    let stride = torque_stride.max(total_torque.div_ceil(max_fit.max(1)));
    let total_n: usize = ms.iter().map(|m| m.n).sum();
    let tstride = temp_stride.max(total_n.div_ceil(max_fit.max(1)));
    let mut u = 0;
    ms.into_iter()
        .zip(profiles)
        .map(|(m, q)| {
            let facts = Channel::ALL.map(|c| q.get(c.column()).cloned().unwrap_or_default());
            let mut f = File {
                fit: Samples::new(&m, stride, tstride),
                all: Samples::new(&m, 1, temp_stride),
                unit0: u,
                m,
                sigma: vec![1.0; Channel::ALL.len()],
                disk: None,
                held: facts.iter().map(|x| x.held).collect(),
                grid: facts.iter().map(|x| x.grid).collect(),
            };
            for (c, x) in Channel::ALL.into_iter().zip(&facts) {
                compared(&mut f, c, x);
            }
            u += f.m.seg.blocks.len().max(1);
            f
        })
        .collect()
}

/// Leaves out of every comparison what the data-quality stage says is not a reading of channel
/// `c` ([`Facts`]):
/// - a constant channel (exact zeros of an unused clutch) entirely: its floor would be its
///   quantisation step, and the tolerance of its subsystem would swamp the live channels';
/// - spike and dropout samples (bridged in the inputs): a fraction of a percent of the samples,
///   hundreds of floors off, would dominate the sum of squares and read as a gap;
/// - of a held channel, every sample but the first after each change of the reading: the copies
///   are one reading counted again, each staler than the last (counted, thermocouples held at
///   1 Hz read as a sensor lag).
fn compared(f: &mut File, c: Channel, x: &Facts) {
    let v = series(&f.m, c);
    for s in [&mut f.fit, &mut f.all] {
        let idx = &mut s.idx[c.index()];
        if x.constant.is_some() {
            idx.clear();
            continue;
        }
        idx.retain(|k| x.bad.binary_search(k).is_err());
        if let (Some(_), Some(v)) = (x.held, v) {
            let mut prev: Option<usize> = None;
            idx.retain(|&k| {
                let fresh = prev.is_none_or(|p| v[k].to_bits() != v[p].to_bits());
                prev = Some(k);
                fresh
            });
        }
    }
}

/// Number of bootstrap units (event blocks) of a set of records.
pub fn units(files: &[File]) -> usize {
    files
        .iter()
        .map(|f| f.m.seg.blocks.len().max(1))
        .sum::<usize>()
        .max(1)
}

/// The one residual iterator: calls `f(file, channel, sample, residual)` for every finite
/// residual (measured − predicted) of `chans` at the fit or score samples.
pub fn for_each_residual(
    files: &[File],
    preds: &[Predictions],
    chans: &[Channel],
    fit: bool,
    mut f: impl FnMut(&File, Channel, usize, f64),
) {
    for (file, pr) in files.iter().zip(preds) {
        let s = if fit { &file.fit } else { &file.all };
        for &c in chans {
            let y = &pr.y[c.index()];
            if y.is_empty() {
                continue;
            }
            for &k in s.get(c) {
                let e = predict::measured(&file.m, c, k) - y[k];
                if e.is_finite() {
                    f(file, c, k, e);
                }
            }
        }
    }
}

/// Predictions of a model on every record (with each record's cached disk estimate when
/// `cached_disk`, unless the model's sensor terms correct the inputs the estimate was made from:
/// a torque class fitted beside a thermocouple lag must see the disk of the un-lagged readings).
pub fn predictions(
    model: &Model,
    files: &[File],
    chans: &[Channel],
    fit: bool,
    cached_disk: bool,
) -> Vec<Predictions> {
    files
        .iter()
        .map(|f| {
            let s = if fit { &f.fit } else { &f.all };
            predict_file(model, f, s, chans, cached_disk, None)
        })
        .collect()
}

/// [`predictions`] on the fit samples for the evaluations of one fit: each record's corrected
/// inputs and disk replay are taken from its `memo` when the model leaves them as they were
/// ([`predict::predict_reusing`]); the results' `disk` is `None`.
pub fn fit_predictions(
    model: &Model,
    files: &[File],
    chans: &[Channel],
    cached_disk: bool,
    memo: &mut [predict::ReplayMemo],
) -> Vec<Predictions> {
    files
        .iter()
        .zip(memo)
        .map(|(f, memo)| predict_file(model, f, &f.fit, chans, cached_disk, Some(memo)))
        .collect()
}

/// One record's predictions: from its cached disk estimate when allowed, else replayed (through
/// `memo` when given).
fn predict_file(
    model: &Model,
    f: &File,
    s: &Samples,
    chans: &[Channel],
    cached_disk: bool,
    memo: Option<&mut predict::ReplayMemo>,
) -> Predictions {
    let cached = cached_disk && !predict::corrects_inputs(&model.terms);
    match (&f.disk, cached, memo) {
        (Some(d), true, memo) => predict::predict_with_disk_ref(model, &f.m, s, chans, d, memo),
        (_, _, Some(memo)) => predict::predict_reusing(model, &f.m, s, chans, memo),
        (_, _, None) => predict::predict(model, &f.m, s, chans),
    }
}

/// Per-channel sums of a model over a set of records.
#[derive(Debug, Clone, PartialEq)]
pub struct Scores {
    /// Per channel: sum of squared residuals and count.
    pub sse: Vec<f64>,
    pub n: Vec<usize>,
    /// Per channel and unit: sum of squared residuals.
    pub unit_sse: Vec<Vec<f64>>,
    /// Per channel: sum of squared standardized residuals (each record's σ).
    pub std_sse: Vec<f64>,
    /// Per channel and unit: the same, and the counts.
    pub std_unit: Vec<Vec<f64>>,
    pub unit_n: Vec<Vec<f64>>,
    /// Per channel and unit: Σ (tolerance/σ)², the practical tolerance in standardized units.
    pub unit_tol: Vec<Vec<f64>>,
    /// Predictions per record.
    pub preds: Vec<Predictions>,
}

impl Scores {
    /// Scores of `preds` on `chans`.
    pub fn new(files: &[File], preds: Vec<Predictions>, chans: &[Channel], nunits: usize) -> Self {
        let nc = Channel::ALL.len();
        let mut s = Scores {
            sse: vec![0.0; nc],
            n: vec![0; nc],
            unit_sse: vec![vec![0.0; nunits]; nc],
            std_sse: vec![0.0; nc],
            std_unit: vec![vec![0.0; nunits]; nc],
            unit_n: vec![vec![0.0; nunits]; nc],
            unit_tol: vec![vec![0.0; nunits]; nc],
            preds: Vec::new(),
        };
        for_each_residual(files, &preds, chans, false, |f, c, k, e| {
            let i = c.index();
            let sg = f.sigma[i];
            let z2 = e * e / (sg * sg);
            let u = (f.unit0 + f.m.seg.block_of(k)).min(nunits - 1);
            s.sse[i] += e * e;
            s.std_sse[i] += z2;
            s.n[i] += 1;
            s.unit_sse[i][u] += e * e;
            s.std_unit[i][u] += z2;
            s.unit_n[i][u] += 1.0;
            s.unit_tol[i][u] += (c.tolerance() / sg).powi(2);
        });
        s.preds = preds;
        s
    }

    /// Scores of a model on the score samples.
    pub fn of(model: &Model, files: &[File], chans: &[Channel], nunits: usize) -> Self {
        Scores::new(
            files,
            predictions(model, files, chans, false, false),
            chans,
            nunits,
        )
    }

    /// Standardized SSE per unit summed over `chans`.
    pub fn unit_std(&self, chans: &[Channel]) -> Vec<f64> {
        sum_rows(&self.std_unit, chans)
    }

    /// Per unit, how much the standardized squares over `chans` fell from `self` to `after`
    /// (a gain when positive).
    pub fn unit_gain_to(&self, after: &Scores, chans: &[Channel]) -> Vec<f64> {
        self.unit_std(chans)
            .iter()
            .zip(&after.unit_std(chans))
            .map(|(a, b)| a - b)
            .collect()
    }

    /// Sample count per unit summed over `chans`.
    pub fn unit_count(&self, chans: &[Channel]) -> Vec<f64> {
        sum_rows(&self.unit_n, chans)
    }

    /// Practical tolerance per unit summed over `chans` (standardized units).
    pub fn unit_tolerance(&self, chans: &[Channel]) -> Vec<f64> {
        sum_rows(&self.unit_tol, chans)
    }

    /// Σ z² and n over `chans`.
    pub fn total(&self, chans: &[Channel]) -> (f64, f64) {
        chans.iter().fold((0.0, 0.0), |(a, n), c| {
            (a + self.std_sse[c.index()], n + self.n[c.index()] as f64)
        })
    }

    /// Replaces the channels `chans` by those of `other` (a candidate that only changes them).
    pub fn with(&self, other: &Scores, chans: &[Channel]) -> Scores {
        let mut s = self.clone();
        for c in chans {
            let i = c.index();
            s.sse[i] = other.sse[i];
            s.n[i] = other.n[i];
            s.unit_sse[i] = other.unit_sse[i].clone();
            s.std_sse[i] = other.std_sse[i];
            s.std_unit[i] = other.std_unit[i].clone();
            s.unit_n[i] = other.unit_n[i].clone();
            s.unit_tol[i] = other.unit_tol[i].clone();
            for (p, o) in s.preds.iter_mut().zip(&other.preds) {
                p.y[i].clone_from(&o.y[i]);
            }
        }
        s
    }
}

fn sum_rows(rows: &[Vec<f64>], chans: &[Channel]) -> Vec<f64> {
    let nunits = rows.first().map_or(0, Vec::len);
    let mut u = vec![0.0; nunits];
    for c in chans {
        for (j, v) in rows[c.index()].iter().enumerate() {
            u[j] += v;
        }
    }
    u
}

/// Quantisation step of a channel's measurement (the DBC's factor).
fn quantum(c: Channel) -> f64 {
    use crate::can::messages::{BenchTemps, BenchTorque, DctActuators, EngStatus};
    match c {
        Channel::Torque(0) => BenchTorque::CLUTCH1_TORQUE_FACTOR,
        Channel::Torque(_) => BenchTorque::CLUTCH2_TORQUE_FACTOR,
        Channel::Temp(0) => BenchTemps::PRESSURE_PLATE1_TEMP_FACTOR,
        Channel::Temp(1) => BenchTemps::PRESSURE_PLATE2_TEMP_FACTOR,
        Channel::Temp(_) => BenchTemps::CENTRAL_DISK_TEMP_FACTOR,
        Channel::Pos(0) => DctActuators::CLUTCH1_POS_FACTOR,
        Channel::Pos(_) => DctActuators::CLUTCH2_POS_FACTOR,
        Channel::Engine => EngStatus::ENG_TORQUE_ACT_FACTOR,
    }
}

/// Noise floor σ of one channel from residuals `r` at consecutive samples (`None` where the
/// samples are not consecutive).
pub fn noise_sigma(diffs: &mut [f64], rms: f64, q: f64) -> f64 {
    let q = q / 12f64.sqrt();
    if diffs.len() < 10 {
        return q.max(1e-9);
    }
    diffs.sort_by(f64::total_cmp);
    let keep = &diffs[..(diffs.len() * 98).div_ceil(100).max(1)];
    let trimmed = keep.iter().sum::<f64>() / keep.len() as f64;
    let diff_sigma = (trimmed / TRIM_CONSISTENCY / 2.0).sqrt();
    diff_sigma.min(rms).max(q)
}

/// The measured series of channel `c` at the record's rate (the engine's is compared as window
/// means: `None`).
fn series(m: &Measured, c: Channel) -> Option<&[f64]> {
    match c {
        Channel::Torque(i) => Some(&m.torque[i]),
        Channel::Temp(0) => Some(&m.pp[0]),
        Channel::Temp(1) => Some(&m.pp[1]),
        Channel::Temp(_) => Some(&m.cd),
        Channel::Pos(i) => Some(&m.x[i]),
        Channel::Engine => None,
    }
}

/// Sets the noise floor of every channel of every record from its residuals under `model`;
/// returns the pooled σ per channel.
pub fn set_noise(model: &Model, files: &mut [File]) -> Vec<f64> {
    let nc = Channel::ALL.len();
    let mut pooled = vec![(0.0f64, 0usize); nc];
    for f in files.iter_mut() {
        let pr = predict::predict(model, &f.m, &f.all, &Channel::ALL);
        for c in Channel::ALL {
            let y = &pr.y[c.index()];
            let mut d2 = Vec::new();
            let (mut ss, mut n) = (0.0, 0usize);
            // A held channel's equal readings are one sample copied, not two: only pairs that
            // straddle an update carry the noise (else the floor collapses).
            let every = f.held[c.index()];
            let held = every.is_some();
            // A held channel is compared at its updates only: consecutive compared samples
            // are a hold apart.
            let max_gap = every.map_or(20, |e| 20.max(2 * e + f.all.temp_stride));
            if !y.is_empty() {
                for w in f.all.get(c).windows(2) {
                    let (a, b) = (w[0], w[1]);
                    if b - a > max_gap {
                        continue;
                    }
                    let (ma, mb) = (predict::measured(&f.m, c, a), predict::measured(&f.m, c, b));
                    if held && ma.to_bits() == mb.to_bits() {
                        continue;
                    }
                    let (ra, rb) = (ma - y[a], mb - y[b]);
                    let d = rb - ra;
                    if d.is_finite() {
                        d2.push(d * d);
                        ss += ra * ra;
                        n += 1;
                    }
                }
            }
            let rms = (ss / n.max(1) as f64).sqrt();
            // A logger's coarser grid than the DBC's bounds the floor as the DBC's step does.
            let grid = f.grid[c.index()];
            let sigma = noise_sigma(&mut d2, rms, quantum(c).max(grid.unwrap_or(0.0)));
            f.sigma[c.index()] = sigma;
            if n > 0 {
                pooled[c.index()].0 += sigma * sigma * n as f64;
                pooled[c.index()].1 += n;
            }
        }
    }
    pooled
        .iter()
        .map(|(s2, n)| {
            if *n > 0 {
                (s2 / *n as f64).sqrt()
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// Caches each record's disk temperature estimate under `model`.
pub fn cache_disk(model: &Model, files: &mut [File]) {
    for f in files.iter_mut() {
        let h = SetHooks::of(model);
        f.disk = Some(crate::gap::eval::replay::disk_estimate(&model.p, &h, &f.m));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::fit::stats::Rng;

    #[test]
    fn noise_floor_is_unbiased_for_white_gaussian_noise() {
        let mut rng = Rng::new(7);
        let sigma = 0.5;
        let r: Vec<f64> = (0..200_000).map(|_| sigma * rng.normal()).collect();
        let mut d2: Vec<f64> = r.windows(2).map(|w| (w[1] - w[0]).powi(2)).collect();
        let rms = (r.iter().map(|x| x * x).sum::<f64>() / r.len() as f64).sqrt();
        let s = noise_sigma(&mut d2, rms, 1e-6);
        assert!((s / sigma - 1.0).abs() < 0.01, "{s}");
    }

    #[test]
    fn noise_floor_ignores_a_smooth_model_error() {
        let mut rng = Rng::new(8);
        let r: Vec<f64> = (0..50_000)
            .map(|k| 3.0 * (k as f64 * 1e-3).sin() + 0.3 * rng.normal())
            .collect();
        let mut d2: Vec<f64> = r.windows(2).map(|w| (w[1] - w[0]).powi(2)).collect();
        let rms = (r.iter().map(|x| x * x).sum::<f64>() / r.len() as f64).sqrt();
        let s = noise_sigma(&mut d2, rms, 1e-6);
        assert!((s / 0.3 - 1.0).abs() < 0.02, "{s}");
    }
}

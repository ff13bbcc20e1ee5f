//! Where the gap lies (DESIGN.md §6 step 3): which subsystems' residuals exceed their noise
//! floor, bias maps of the torque-characteristic residual over clutch temperature × slip × x_to
//! bins (mean residual per bin, z test with an autocorrelation-corrected sample size, false
//! discovery rate controlled by Benjamini–Hochberg), and flagged time segments (event blocks whose
//! standardized residual exceeds the noise, also under BH).

#![allow(clippy::needless_range_loop)]

use crate::gap::eval::predict::{self, Predictions, Samples};
use crate::gap::fit::lsq;
use crate::gap::fit::stats;
use crate::gap::model::candidate::{Channel, Model};
use crate::gap::record::measured::Measured;
use crate::model::effects::Subsystem;

/// Bin edges of the bias maps.
pub const THETA_EDGES: [f64; 7] = [
    f64::NEG_INFINITY,
    50.0,
    100.0,
    150.0,
    200.0,
    250.0,
    f64::INFINITY,
];
pub const SLIP_EDGES: [f64; 5] = [0.0, 5.0, 50.0, 150.0, f64::INFINITY];
pub const X_EDGES: [f64; 6] = [f64::NEG_INFINITY, 4.5, 5.0, 5.5, 6.0, f64::INFINITY];

/// Residual evidence of one subsystem.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ResidualSubsystem {
    pub subsystem: Subsystem,
    /// Mean squared standardized residual minus 1, in % (0 = sensor noise).
    pub excess_pct: f64,
    /// z statistic of the excess (autocorrelation-corrected).
    pub z: f64,
    pub significant: bool,
    /// (output, RMSE, noise floor).
    pub outputs: Vec<(String, f64, f64)>,
}

/// One bin of a bias map.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BiasCell {
    pub theta_c: (f64, f64),
    pub slip_radps: (f64, f64),
    pub x_to_mm: (f64, f64),
    pub n: usize,
    /// Mean residual (N·m).
    pub mean: f64,
    pub z: f64,
    pub p: f64,
    pub flagged: bool,
}

/// A bias map of an output's residual.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BiasMap {
    pub output: String,
    pub model: String,
    pub cells: Vec<BiasCell>,
    pub tested: usize,
    pub flagged: usize,
}

/// A flagged time segment.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Segment {
    pub file: String,
    pub t_start_s: f64,
    pub t_end_s: f64,
    /// Mean squared standardized residual over the checkable outputs.
    pub ms_std: f64,
    /// Output contributing most.
    pub output: String,
    pub p: f64,
}

/// Where the gap lies.
#[derive(Debug, Clone, PartialEq, serde::Serialize, Default)]
pub struct Where {
    /// By decreasing excess.
    pub residual_subsystems: Vec<ResidualSubsystem>,
    /// Bias maps of the recalibrated model's torque residual.
    pub bias_maps: Vec<BiasMap>,
    /// Flagged segments of the validation records (BH-controlled), largest first (at most 30).
    pub flagged_segments: Vec<Segment>,
    /// Segments tested.
    pub segments_tested: usize,
}

fn bin(edges: &[f64], v: f64) -> Option<usize> {
    (0..edges.len() - 1).find(|&j| v >= edges[j] && v < edges[j + 1])
}

/// The index of the bias map's cell of θ_c bin `a`, slip bin `b` and x_to bin `d`.
fn cell_index(a: usize, b: usize, d: usize) -> usize {
    (a * (SLIP_EDGES.len() - 1) + b) * (X_EDGES.len() - 1) + d
}

/// Bias map of the torque residual of `preds` (one per file) over θ_c × slip × x_to.
pub fn bias_map(
    files: &[&Measured],
    samples: &[&Samples],
    preds: &[Predictions],
    label: &str,
    q: f64,
) -> BiasMap {
    let (sums, all) = binned_torque_residuals(files, samples, preds);
    let rho = lsq::lag1_autocorrelation(&all).clamp(0.0, 0.999);
    let infl = (1.0 - rho) / (1.0 + rho);
    let (mut cells, ps) = bias_cells(&sums, infl);
    let rej = stats::benjamini_hochberg(&ps, q);
    for (c, r) in cells.iter_mut().zip(&rej) {
        c.flagged = *r;
    }
    BiasMap {
        output: "T_c (both clutches)".into(),
        model: label.into(),
        tested: cells.len(),
        flagged: cells.iter().filter(|c| c.flagged).count(),
        cells,
    }
}

/// The finite torque residuals of `preds` with a disk replay: per cell of the bias map their
/// count, sum and sum of squares, and all of them in order (those outside every cell too).
fn binned_torque_residuals(
    files: &[&Measured],
    samples: &[&Samples],
    preds: &[Predictions],
) -> (Vec<(usize, f64, f64)>, Vec<f64>) {
    let nb = (THETA_EDGES.len() - 1) * (SLIP_EDGES.len() - 1) * (X_EDGES.len() - 1);
    let mut sums = vec![(0usize, 0.0f64, 0.0f64); nb];
    let mut all = Vec::new();
    for ((m, s), pr) in files.iter().zip(samples).zip(preds) {
        let Some(disk) = &pr.disk else { continue };
        for i in 0..2 {
            let c = Channel::Torque(i);
            let y = &pr.y[c.index()];
            if y.is_empty() {
                continue;
            }
            for &k in s.get(c) {
                let r = m.torque[i][k] - y[k];
                if !r.is_finite() {
                    continue;
                }
                all.push(r);
                let (Some(a), Some(b), Some(d)) = (
                    bin(&THETA_EDGES, disk[i][k]),
                    bin(&SLIP_EDGES, m.slip[i][k].abs()),
                    bin(&X_EDGES, m.x[i][k]),
                ) else {
                    continue;
                };
                let j = cell_index(a, b, d);
                sums[j].0 += 1;
                sums[j].1 += r;
                sums[j].2 += r * r;
            }
        }
    }
    (sums, all)
}

/// The bias map's cells with at least 10 residuals: the mean residual's z test, its sample
/// size inflated by `infl` for the autocorrelation (not yet flagged); and their p-values.
fn bias_cells(sums: &[(usize, f64, f64)], infl: f64) -> (Vec<BiasCell>, Vec<f64>) {
    let mut cells = Vec::new();
    let mut ps = Vec::new();
    for a in 0..THETA_EDGES.len() - 1 {
        for b in 0..SLIP_EDGES.len() - 1 {
            for d in 0..X_EDGES.len() - 1 {
                let (n, s, s2) = sums[cell_index(a, b, d)];
                if n < 10 {
                    continue;
                }
                let mean = s / n as f64;
                let var = (s2 / n as f64 - mean * mean).max(1e-12);
                let neff = (n as f64 * infl).max(2.0);
                let z = mean / (var / neff).sqrt();
                let p = stats::p_two_sided(z);
                ps.push(p);
                cells.push(BiasCell {
                    theta_c: (THETA_EDGES[a], THETA_EDGES[a + 1]),
                    slip_radps: (SLIP_EDGES[b], SLIP_EDGES[b + 1]),
                    x_to_mm: (X_EDGES[d], X_EDGES[d + 1]),
                    n,
                    mean,
                    z,
                    p,
                    flagged: false,
                });
            }
        }
    }
    (cells, ps)
}

/// Residual subsystems, bias maps and flagged segments of the recalibrated model.
pub fn locate(
    _model: &Model,
    files: &[&Measured],
    samples: &[&Samples],
    preds: &[Predictions],
    sigmas: &[&[f64]],
    chans: &[Channel],
    q: f64,
) -> Where {
    let records = Records {
        files,
        samples,
        preds,
        sigmas,
    };
    let subs = residual_subsystems(&records, chans);
    let (flagged, tested) = flagged_segments(&records, chans, q);
    Where {
        residual_subsystems: subs,
        bias_maps: vec![bias_map(files, samples, preds, "recalibrated", q)],
        flagged_segments: flagged,
        segments_tested: tested,
    }
}

/// The records [`locate`] reads: each file's measured quantities, score samples, predictions
/// and noise floor σ per channel.
struct Records<'a> {
    files: &'a [&'a Measured],
    samples: &'a [&'a Samples],
    preds: &'a [Predictions],
    sigmas: &'a [&'a [f64]],
}

impl Records<'_> {
    /// Each file's measured quantities, samples, predictions and noise floors.
    fn each(&self) -> impl Iterator<Item = (&Measured, &Samples, &Predictions, &[f64])> {
        self.files
            .iter()
            .zip(self.samples)
            .zip(self.preds)
            .zip(self.sigmas)
            .map(|(((m, s), pr), sg)| (*m, *s, pr, *sg))
    }
}

/// The subsystems with a checked channel, by decreasing excess: the mean standardized square
/// of their residuals above 1, its z against noise only, and each output's RMS and noise.
fn residual_subsystems(records: &Records, chans: &[Channel]) -> Vec<ResidualSubsystem> {
    let mut subs: Vec<ResidualSubsystem> = Vec::new();
    let subsystems = [
        Subsystem::TorqueCharacteristic,
        Subsystem::Thermal,
        Subsystem::Actuator,
        Subsystem::Engine,
    ];
    for sub in subsystems {
        let cs: Vec<Channel> = chans
            .iter()
            .copied()
            .filter(|c| c.subsystem() == sub)
            .collect();
        if cs.is_empty() {
            continue;
        }
        let mut s_std = 0.0;
        let mut n = 0.0;
        let mut neff = 0.0;
        let mut outputs = Vec::new();
        for c in &cs {
            let (r, z2, s2) = channel_residuals(*c, records);
            if r.is_empty() {
                continue;
            }
            let mse = r.iter().map(|e| e * e).sum::<f64>() / r.len() as f64;
            s_std += z2;
            n += r.len() as f64;
            neff += lsq::effective_n(&r);
            outputs.push((
                c.name().to_string(),
                mse.sqrt(),
                (s2 / r.len() as f64).sqrt(),
            ));
        }
        if n == 0.0 {
            continue;
        }
        let excess = s_std / n - 1.0;
        // Under noise only, the mean of n_eff independent χ²₁ has sd √(2/n_eff).
        let z = excess / (2.0 / neff.max(1.0)).sqrt();
        subs.push(ResidualSubsystem {
            subsystem: sub,
            excess_pct: 100.0 * excess,
            z,
            significant: z > 4.0 && excess > 0.05,
            outputs,
        });
    }
    subs.sort_by(|a, b| b.excess_pct.total_cmp(&a.excess_pct));
    subs
}

/// Channel `c`'s finite residuals over every file in order, the sum of their squares over
/// the noise variance, and the sum of the noise variance over them.
fn channel_residuals(c: Channel, records: &Records) -> (Vec<f64>, f64, f64) {
    let mut r = Vec::new();
    let mut z2 = 0.0;
    let mut s2 = 0.0;
    for (m, s, pr, sg) in records.each() {
        let y = &pr.y[c.index()];
        if y.is_empty() {
            continue;
        }
        let sig = sg[c.index()];
        for &k in s.get(c) {
            let e = predict::measured(m, c, k) - y[k];
            if e.is_finite() {
                r.push(e);
                z2 += e * e / (sig * sig);
                s2 += sig * sig;
            }
        }
    }
    (r, z2, s2)
}

/// The flagged segments (at most 30, largest first) among the event blocks of every file,
/// under Benjamini–Hochberg at `q`, and the number of blocks tested.
fn flagged_segments(records: &Records, chans: &[Channel], q: f64) -> (Vec<Segment>, usize) {
    let mut segs = Vec::new();
    for (m, s, pr, sg) in records.each() {
        for &block in &m.seg.blocks {
            segs.extend(block_segment(m, s, pr, sg, chans, block));
        }
    }
    let ps: Vec<f64> = segs.iter().map(|s| s.p).collect();
    let rej = stats::benjamini_hochberg(&ps, q);
    let tested = segs.len();
    let mut flagged: Vec<Segment> = segs
        .into_iter()
        .zip(rej)
        .filter(|(s, r)| *r && s.ms_std > 1.2)
        .map(|(s, _)| s)
        .collect();
    flagged.sort_by(|a, b| b.ms_std.total_cmp(&a.ms_std));
    flagged.truncate(30);
    (flagged, tested)
}

/// The segment of event block `[a, b)` of one file: the mean standardized square of its
/// residuals, the output contributing most and the p-value of noise only; `None` with fewer
/// than 20 residuals.
fn block_segment(
    m: &Measured,
    s: &Samples,
    pr: &Predictions,
    sg: &[f64],
    chans: &[Channel],
    (a, b): (usize, usize),
) -> Option<Segment> {
    let mut s_std = 0.0;
    let mut n = 0.0;
    let mut worst = (0.0, "");
    for c in chans {
        let y = &pr.y[c.index()];
        if y.is_empty() {
            continue;
        }
        let sig = sg[c.index()];
        let idx = s.get(*c);
        let lo = idx.partition_point(|&k| k < a);
        let hi = idx.partition_point(|&k| k < b);
        let mut sc = 0.0;
        for &k in &idx[lo..hi] {
            let e = (predict::measured(m, *c, k) - y[k]) / sig;
            if e.is_finite() {
                sc += e * e;
                n += 1.0;
            }
        }
        s_std += sc;
        if sc > worst.0 {
            worst = (sc, c.name());
        }
    }
    if n < 20.0 {
        return None;
    }
    let ms = s_std / n;
    // Residual samples inside a block are correlated: count at most one independent
    // sample per 10 (0.1 s).
    let neff = (n / 10.0).max(2.0);
    let z = (ms - 1.0) / (2.0 / neff).sqrt();
    let p = 1.0 - stats::normal_cdf(z);
    Some(Segment {
        file: m.source.clone(),
        t_start_s: m.time[a],
        t_end_s: m.time[b.saturating_sub(1)],
        ms_std: ms,
        output: worst.1.to_string(),
        p,
    })
}

//! The sim-to-real gap diagnosis (DESIGN.md §6): given training and validation records from
//! "reality" and the nominal parameters, where is the gap, which unmodelled effect causes it, and
//! how far does it shrink once that effect is added — judged on the validation records only.
//!
//! Pipeline:
//! 1. Channels the records can check (per subsystem, from the logged columns) and what they can
//!    tell apart ([`separability`]).
//! 2. Plain recalibration: the nominal parameters re-fitted per subsystem group — thermal (α1,
//!    α2, α3, α5, α8, α9 on the plate and central-disk temperatures), torque characteristic (λ0,
//!    λ1, λ2 of (9) on the torque, with the recalibrated thermal model), actuator (lag τ) —
//!    so that an effect is credited only for what recalibration cannot do.
//! 3. Every library effect fitted jointly with its group's recalibration parameters on the
//!    training records; scored by ΔBIC on training (autocorrelation-corrected sample sizes) and by
//!    the standardized validation error over every checkable channel (each channel's residual
//!    divided by its sensor-noise floor), with a paired event bootstrap over validation blocks.
//!    An effect is credited when ΔBIC < −10, its validation improvement is significant and it
//!    removes at least 10 % of the recalibrated validation excess over the noise floor.
//! 4. Ambiguity: credited effects whose validation score is not significantly worse than the
//!    best's. Outside the library: a black-box discrepancy of the torque characteristic
//!    ([`super::blackbox`]) that explains far more of the validation torque gap than the best
//!    effect, with the variables it needs. `none`: nothing credited and nothing significant left.
//! 5. How far: RMSE and fit % of every output before (nominal, recalibrated) and after the effect,
//!    with event-bootstrap intervals; equation error and replay error.

use super::blackbox::{self, BlackBoxResult, Design};
use super::candidates::{self, Channel, Model, Predictions, Samples};
use super::dataset::{Col, Dataset};
use super::events::SegmentOptions;
use super::finding::Finding;
use super::keys;
use super::lsq::{self, LmOptions, ParamSpec};
use super::replay::{self, Measured};
use super::stats::{self, Rng};
use super::where_::{self, Where};
use crate::model::effects::{EffectId, EffectSet, Subsystem};
use crate::model::params::Params;
use std::collections::BTreeMap;

/// Options of the diagnosis.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnoseOptions {
    pub seg: SegmentOptions,
    /// Every how many torque samples a fit uses (validation uses all).
    pub torque_stride: usize,
    /// Every how many samples a temperature residual is taken.
    pub temp_stride: usize,
    /// Bootstrap resamples.
    pub bootstrap: usize,
    pub seed: u64,
    /// Friction energy accumulates across files in the given order (default: from the start of
    /// each file, as the plant counts it per run).
    pub carry_energy: bool,
    /// ΔBIC below which an effect is supported by the training data.
    pub bic_threshold: f64,
    /// Share of the recalibrated validation excess an effect must remove to be credited.
    pub min_gap_reduction: f64,
    /// Outside the library when the black box explains at least this share of the validation
    /// torque excess…
    pub outside_min_share: f64,
    /// …and at least this much more than the best effect.
    pub outside_margin: f64,
    /// False discovery rate of the bias maps and flagged segments.
    pub fdr_q: f64,
    /// Largest number of samples per channel in a fit (longer records are thinned further).
    pub max_fit_samples: usize,
    /// An effect is credited only when its fitted magnitude reaches this fraction of the
    /// smallest documented plausible magnitude.
    pub min_effect_fraction: f64,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            seg: SegmentOptions::default(),
            torque_stride: 3,
            temp_stride: 10,
            bootstrap: 400,
            seed: 1,
            carry_energy: false,
            bic_threshold: -10.0,
            min_gap_reduction: 0.10,
            outside_min_share: 0.4,
            outside_margin: 0.25,
            fdr_q: 0.05,
            max_fit_samples: 40_000,
            min_effect_fraction: 0.25,
        }
    }
}

/// Errors of the diagnosis.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DiagnoseError {
    #[error("no training file given")]
    NoTraining,
    #[error("no validation file given (the diagnosis ranks effects on held-out data)")]
    NoValidation,
    #[error("no channel can be checked: the records have no slipping clutch and no temperatures")]
    NothingCheckable,
}

/// A group of channels fitted together, with the parameters plain recalibration may change.
#[derive(Debug, Clone, PartialEq)]
struct Group {
    subsystem: Subsystem,
    channels: Vec<Channel>,
    recal: Vec<&'static str>,
}

fn groups() -> Vec<Group> {
    vec![
        Group {
            subsystem: Subsystem::Thermal,
            channels: vec![Channel::Temp(0), Channel::Temp(1), Channel::Temp(2)],
            // The terms the plate and central-disk temperatures determine directly: convection
            // (α2, α8) and heating gains (α3, α9). The conduction terms to the unmeasured disk
            // (α1, α4, α5) are left to `ddct identify`: re-fitting them here trades validation
            // accuracy for training fit.
            recal: vec![
                "thermal5.alpha2_per_s",
                "thermal5.alpha3_k_per_j",
                "thermal5.alpha8_per_s",
                "thermal5.alpha9_k_per_j",
            ],
        },
        Group {
            subsystem: Subsystem::TorqueCharacteristic,
            channels: vec![Channel::Torque(0), Channel::Torque(1)],
            recal: vec![
                "clutch.x_isp0_mm",
                "clutch.x_isp1_mm_per_c",
                "clutch.x_isp2_mm_per_c2",
            ],
        },
        Group {
            subsystem: Subsystem::Actuator,
            channels: vec![Channel::Pos(0), Channel::Pos(1)],
            recal: vec!["actuator.tau_s"],
        },
        Group {
            subsystem: Subsystem::Engine,
            channels: vec![Channel::Engine],
            recal: vec![],
        },
    ]
}

/// The group whose channels an effect is fitted on (backlash acts between the measured actuator
/// and the bearing, so it shows in the torque characteristic's residual).
fn fit_group_of(id: EffectId) -> Subsystem {
    match id {
        EffectId::ActuatorBacklash => Subsystem::TorqueCharacteristic,
        other => other.subsystem(),
    }
}

/// One file prepared for the diagnosis.
struct File {
    m: Measured,
    /// Samples for fitting (thinned).
    fit: Samples,
    /// Samples for scoring (all).
    all: Samples,
    /// Global block offset (bootstrap units).
    unit0: usize,
    /// Noise floor σ per channel of this file (its own sensors and operating conditions).
    sigma: Vec<f64>,
}

fn prepare(ds: &[Dataset], p: &Params, o: &DiagnoseOptions, unit0: usize) -> Vec<File> {
    let ms = if o.carry_energy {
        Measured::sequence(ds, p, &o.seg)
    } else {
        ds.iter()
            .map(|d| Measured::new(d, p, [0.0; 2], &o.seg))
            .collect()
    };
    let total_torque: usize = ms
        .iter()
        .map(|m| m.torque_idx[0].len() + m.torque_idx[1].len())
        .sum();
    let stride = o
        .torque_stride
        .max(total_torque.div_ceil(o.max_fit_samples.max(1)));
    let total_n: usize = ms.iter().map(|m| m.n).sum();
    let tstride = o
        .temp_stride
        .max(total_n.div_ceil(o.max_fit_samples.max(1)));
    let mut u = unit0;
    ms.into_iter()
        .map(|m| {
            let fit = Samples::new(&m, stride, tstride);
            let all = Samples::new(&m, 1, o.temp_stride);
            let f = File {
                fit,
                all,
                unit0: u,
                m,
                sigma: vec![1.0; Channel::ALL.len()],
            };
            u += f.m.seg.blocks.len().max(1);
            f
        })
        .collect()
}

fn units(files: &[File]) -> usize {
    files
        .iter()
        .map(|f| f.m.seg.blocks.len().max(1))
        .sum::<usize>()
        .max(1)
}

/// Per-channel sums over a set of files for one model.
#[derive(Debug, Clone, PartialEq)]
struct Scores {
    /// Per channel: sum of squared residuals and count.
    sse: Vec<f64>,
    n: Vec<usize>,
    /// Per channel and unit: sum of squared residuals.
    unit_sse: Vec<Vec<f64>>,
    /// Per channel: sum of squared standardized residuals (each file's σ).
    std_sse: Vec<f64>,
    /// Per channel and unit: the same.
    std_unit: Vec<Vec<f64>>,
    /// Predictions per file (for plots and the black box).
    preds: Vec<Predictions>,
}

fn score(model: &Model, files: &[File], chans: &[Channel], nunits: usize, fit: bool) -> Scores {
    let nc = Channel::ALL.len();
    let mut sse = vec![0.0; nc];
    let mut n = vec![0usize; nc];
    let mut unit_sse = vec![vec![0.0; nunits]; nc];
    let mut std_sse = vec![0.0; nc];
    let mut std_unit = vec![vec![0.0; nunits]; nc];
    let mut preds = Vec::with_capacity(files.len());
    for f in files {
        let s = if fit { &f.fit } else { &f.all };
        let pr = candidates::predict(model, &f.m, s, chans);
        for &c in chans {
            let y = &pr.y[c.index()];
            if y.is_empty() {
                continue;
            }
            for &k in s.get(c) {
                let e = candidates::measured(&f.m, c, k) - y[k];
                if e.is_finite() {
                    let z2 = e * e / (f.sigma[c.index()] * f.sigma[c.index()]);
                    sse[c.index()] += e * e;
                    std_sse[c.index()] += z2;
                    n[c.index()] += 1;
                    let u = (f.unit0 + f.m.seg.block_of(k)).min(nunits - 1);
                    unit_sse[c.index()][u] += e * e;
                    std_unit[c.index()][u] += z2;
                }
            }
        }
        preds.push(pr);
    }
    Scores {
        sse,
        n,
        unit_sse,
        std_sse,
        std_unit,
        preds,
    }
}

/// Noise floor (σ) of each channel of each file from that file's residuals under `model`:
/// differences of consecutive residuals (smooth model errors cancel; white sensor noise and the
/// noise of measured inputs, e.g. the slip at a few rpm, do not), at most the residual RMS
/// itself, floored at the quantisation of the signal. Returns the pooled σ per channel.
fn set_noise(model: &Model, files: &mut [File]) -> Vec<f64> {
    let nc = Channel::ALL.len();
    let mut pooled = vec![(0.0f64, 0usize); nc];
    for f in files.iter_mut() {
        let pr = candidates::predict(model, &f.m, &f.all, &Channel::ALL);
        for c in Channel::ALL {
            let q = match c {
                Channel::Torque(_) => 0.1,
                Channel::Temp(_) => 0.1,
                Channel::Pos(_) => 0.001,
                Channel::Engine => 0.1,
            } / 12f64.sqrt();
            let y = &pr.y[c.index()];
            let mut d2 = Vec::new();
            let (mut ss, mut n) = (0.0, 0usize);
            if !y.is_empty() {
                for w in f.all.get(c).windows(2) {
                    let (a, b) = (w[0], w[1]);
                    if b - a > 20 {
                        continue;
                    }
                    let ra = candidates::measured(&f.m, c, a) - y[a];
                    let rb = candidates::measured(&f.m, c, b) - y[b];
                    let d = rb - ra;
                    if d.is_finite() {
                        d2.push(d * d);
                        ss += ra * ra;
                        n += 1;
                    }
                }
            }
            let sigma = if d2.len() < 10 {
                q.max(1e-9)
            } else {
                // E[Δr²] = 2σ² for white noise; the largest 2 % (transients) are trimmed. (A
                // median of |Δr| is biased for quantised signals.)
                d2.sort_by(f64::total_cmp);
                let keep = &d2[..(d2.len() * 98).div_ceil(100).max(1)];
                let diff_sigma = (keep.iter().sum::<f64>() / keep.len() as f64 / 2.0).sqrt();
                let rms = (ss / n.max(1) as f64).sqrt();
                diff_sigma.min(rms).max(q)
            };
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

/// Fits `effect` (if any) together with the recalibration parameters of `group` on the
/// training files, starting from `base`. Returns the fitted model and the fit.
fn fit_group(
    base: &Model,
    group: &Group,
    effect: Option<EffectId>,
    files: &[File],
) -> (Model, Option<lsq::Fit>) {
    let mut specs: Vec<ParamSpec> = Vec::new();
    if let Some(id) = effect {
        for ps in id.params() {
            let (lo, hi) = ps.bounds;
            let scale = (ps.plausible.1 - ps.plausible.0).abs().max(1e-12);
            specs.push(ParamSpec::new(
                format!("{}.{}", id.as_str(), ps.name),
                ps.typical,
                lo,
                hi,
                scale,
            ));
        }
    }
    let ne = specs.len();
    for k in &group.recal {
        let v = keys::get(&base.p, k).unwrap_or(0.0);
        let (lo, hi) = keys::range(k).unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
        if k.starts_with("thermal5.") || *k == "actuator.tau_s" {
            let v0 = v.abs().max(1e-9);
            specs.push(
                ParamSpec::new(*k, v, lo.max(v0 / 10.0), hi.min(v0 * 10.0), keys::scale(k)).log(),
            );
        } else {
            specs.push(ParamSpec::new(*k, v, lo, hi, keys::scale(k)));
        }
    }
    if specs.is_empty() {
        return (*base, None);
    }
    let chans = &group.channels;
    let n: usize = files.iter().map(|f| f.fit.count(chans)).sum();
    if n == 0 {
        return (*base, None);
    }
    let build = |v: &[f64]| -> Option<Model> {
        let mut m = *base;
        if let Some(id) = effect {
            m.set.set_clamped(id, &v[..ne]);
        }
        for (k, x) in group.recal.iter().zip(&v[ne..]) {
            keys::set(&mut m.p, k, *x);
        }
        m.p.clutch.validate().ok()?;
        Some(m)
    };
    let mut buf = Vec::with_capacity(n);
    let mut f = |v: &[f64], r: &mut [f64]| match build(v) {
        Some(model) => {
            buf.clear();
            for file in files {
                let pr = candidates::predict(&model, &file.m, &file.fit, chans);
                for &c in chans {
                    let y = &pr.y[c.index()];
                    for &k in file.fit.get(c) {
                        let e = candidates::measured(&file.m, c, k) - y[k];
                        buf.push(e / file.sigma[c.index()]);
                    }
                }
            }
            for (ri, b) in r.iter_mut().zip(&buf) {
                *ri = if b.is_finite() { *b } else { 1e3 };
            }
        }
        None => r.iter_mut().for_each(|x| *x = 1e6),
    };
    let fit = lsq::levenberg_marquardt(
        &mut f,
        n,
        &specs,
        LmOptions {
            max_iter: 40,
            tol_sse: 1e-7,
            ..LmOptions::default()
        },
    );
    let model = build(&fit.p).unwrap_or(*base);
    (model, Some(fit))
}

/// A subsystem and whether the records can check it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Checkable {
    pub subsystem: String,
    pub checkable: bool,
    /// Outputs used, or why not checkable.
    pub detail: String,
}

/// One ranked candidate.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Ranked {
    pub effect: String,
    pub subsystem: String,
    /// Fitted effect parameters with 95 % intervals.
    pub parameters: BTreeMap<String, f64>,
    pub parameters_ci95: BTreeMap<String, (f64, f64)>,
    /// Recalibrated nominal parameters fitted alongside.
    pub recalibrated: BTreeMap<String, f64>,
    /// Validation RMSE per output.
    pub validation_rmse: BTreeMap<String, f64>,
    /// Validation RMS of the standardized residual over all outputs (1 = sensor noise).
    pub validation_score: f64,
    /// ΔBIC against plain recalibration on the training files (negative favours the effect).
    pub delta_bic: f64,
    /// Share of the recalibrated validation excess over the noise floor the effect removes (%).
    pub gap_explained_pct: f64,
    /// 95 % bootstrap interval of that share (%).
    pub gap_explained_ci95: (f64, f64),
    pub credited: bool,
    pub note: String,
}

/// The verdict.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Verdict {
    /// Subsystem of the diagnosed effect (`none` when nothing remains).
    pub subsystem: String,
    /// Subsystems in order of evidence (the verdict's first).
    pub subsystems: Vec<String>,
    /// An effect identifier, `none` or `outside_library`.
    pub effect: String,
    pub ranking: Vec<Ranked>,
    pub ambiguous_with: Vec<String>,
    pub outside_library_depends_on: Vec<String>,
    pub explanation: String,
    /// The typed findings (issue 17): classes, sensors, out-of-range recalibrations, residuals
    /// outside the library, or `Nothing` alone.
    pub findings: Vec<Finding>,
}

/// Before/after of one output on the validation files.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct OutputGap {
    pub output: String,
    pub subsystem: String,
    pub n: usize,
    /// Sensor-noise floor σ (same unit as the output).
    pub noise: f64,
    pub rmse_nominal: f64,
    pub rmse_recalibrated: f64,
    pub rmse_after: f64,
    pub fit_pct_nominal: f64,
    pub fit_pct_after: f64,
    /// 100·(1 − RMSE_after/RMSE_nominal) with its 95 % event-bootstrap interval.
    pub reduction_pct: f64,
    pub reduction_ci95: (f64, f64),
    /// The same on the gap above each record's noise floor, √max(mean((r/σ)²) − 1, 0).
    pub gap_reduction_pct: f64,
}

/// Replay (free-running) error of an output.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ReplayGap {
    pub output: String,
    pub rmse_nominal: f64,
    pub rmse_after: f64,
}

/// How far the gap shrinks.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct HowFar {
    /// The main output of the verdict's subsystem.
    pub output: String,
    pub rmse_before: f64,
    pub rmse_recalibrated: f64,
    pub rmse_after: f64,
    pub reduction_pct: f64,
    pub reduction_ci95: (f64, f64),
    pub gap_reduction_pct: f64,
    /// Every output, equation error (torque at measured inputs; temperatures from measured
    /// power; positions from requests).
    pub equation_error: Vec<OutputGap>,
    /// Free-running replay from the measured inputs only (torque and temperatures).
    pub replay_error: Vec<ReplayGap>,
}

/// The full diagnosis.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Diagnosis {
    pub train_files: Vec<String>,
    pub validate_files: Vec<String>,
    pub checkable: Vec<Checkable>,
    pub separability: Vec<String>,
    #[serde(rename = "where")]
    pub where_: Where,
    pub verdict: Verdict,
    pub how_far: HowFar,
    /// Plain recalibration: (key, nominal, recalibrated).
    pub recalibration: Vec<(String, f64, f64)>,
    pub blackbox: Option<BlackBoxResult>,
    pub notes: Vec<String>,
    /// The calibrated model (recalibrated parameters + the diagnosed effect).
    #[serde(skip)]
    pub calibrated: Option<(Params, EffectSet)>,
    /// Traces for plots: (file, time, measured, nominal, after) of the main output.
    #[serde(skip)]
    pub traces: Vec<Trace>,
}

/// A trace for the plots.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Trace {
    pub file: String,
    pub output: String,
    pub t: Vec<f64>,
    pub measured: Vec<f64>,
    pub nominal: Vec<f64>,
    pub after: Vec<f64>,
}

/// What the records can check.
pub fn checkability(ds: &[Dataset]) -> Vec<Checkable> {
    let any = |c: Col| ds.iter().any(|d| d.has(c));
    // The engine and the driveline are seen in vehicle records only.
    let vehicle: Vec<&Dataset> = ds.iter().filter(|d| !replay::is_rig_record(d)).collect();
    let engine = vehicle.iter().any(|d| d.has(Col::Te));
    let driveline = !vehicle.is_empty()
        && vehicle
            .iter()
            .all(|d| d.has(Col::Wout) && d.has(Col::GearOdd) && d.has(Col::GearEven));
    vec![
        Checkable {
            subsystem: "torque_characteristic".into(),
            checkable: true,
            detail:
                "T_c1_Nm, T_c2_Nm against (13) at measured x_to, slip and the disk temperature \
                     estimated from th_pp, th_cd, th_h and the measured friction power"
                    .into(),
        },
        Checkable {
            subsystem: "thermal".into(),
            checkable: true,
            detail:
                "th_pp1_C, th_pp2_C, th_cd_C replayed by (16) from the measured friction power \
                     and th_h_C"
                    .into(),
        },
        Checkable {
            subsystem: "actuator".into(),
            checkable: any(Col::X1Req) && any(Col::X2Req),
            detail: if any(Col::X1Req) {
                "x_to1_mm, x_to2_mm replayed from x_to1_req_mm, x_to2_req_mm through the lag".into()
            } else {
                "not checkable: x_to1_req_mm / x_to2_req_mm not logged (TCU_ClutchCmd)".into()
            },
        },
        Checkable {
            subsystem: "engine".into(),
            checkable: engine,
            detail: if engine {
                "T_e_Nm against J_eq·dω_f/dt + T_c1 + T_c2 (18a) where the engine drives".into()
            } else if any(Col::Te) {
                "not checkable: only test-rig records (the dyno replaces the engine)".into()
            } else {
                "not checkable: T_e_Nm not logged (ENG_Status.EngTorqueAct)".into()
            },
        },
        Checkable {
            subsystem: "driveline".into(),
            checkable: driveline,
            detail: if driveline {
                "output balance k_odd·T_c1 + k_even·T_c2 − T_load − J·dω_out/dt reported (no \
                 library effect acts here)"
                    .into()
            } else if vehicle.is_empty() {
                "not checkable: only test-rig records (the output is braked)".into()
            } else {
                "not checkable: w_out_radps and gears not logged".into()
            },
        },
    ]
}

/// Which subsystems the available signals can tell apart.
pub fn separability(checkable: &[Checkable]) -> Vec<String> {
    let has = |s: &str| checkable.iter().any(|c| c.subsystem == s && c.checkable);
    let mut v = vec![
        "torque_characteristic vs thermal: separable — the plate and central-disk temperatures \
         are measured, so a thermal error shows in th_pp/th_cd; the clutch-disk temperature is \
         not measured, so a thermal error of the disk alone reaches the torque residual and is \
         told apart from torque-characteristic effects only by its dynamics"
            .to_string(),
    ];
    if has("actuator") {
        v.push(
            "actuator vs torque_characteristic: separable — x_to is measured and its request is \
             logged; a dead time shows in x_to vs request, a backlash (play between the measured \
             actuator and the bearing) shows as direction-dependent torque at equal measured x_to"
                .into(),
        );
    } else {
        v.push(
            "actuator: a dead time cannot be seen without the position requests; a backlash \
             still shows as direction-dependent torque"
                .into(),
        );
    }
    if has("engine") {
        v.push(
            "engine vs driveline/clutch: separable where the engine drives (vehicle records): \
             the reported engine torque is checked against the measured clutch torques and \
             the flywheel acceleration; on the rig the dyno replaces the engine"
                .into(),
        );
    } else {
        v.push("engine: not checkable without T_e_Nm in vehicle records".into());
    }
    if !has("driveline") {
        v.push(
            "driveline: not checkable without vehicle records with w_out_radps and gears".into(),
        );
    }
    v
}

fn rms_std(s: &Scores, chans: &[Channel]) -> f64 {
    let (mut a, mut n) = (0.0, 0usize);
    for c in chans {
        let i = c.index();
        a += s.std_sse[i];
        n += s.n[i];
    }
    if n == 0 {
        f64::NAN
    } else {
        (a / n as f64).sqrt()
    }
}

/// Standardized per-unit SSE summed over channels.
fn unit_std(s: &Scores, chans: &[Channel], nunits: usize) -> Vec<f64> {
    let mut u = vec![0.0; nunits];
    for c in chans {
        for (j, v) in s.std_unit[c.index()].iter().enumerate() {
            u[j] += v;
        }
    }
    u
}

fn unit_n(files: &[File], chans: &[Channel], nunits: usize) -> Vec<f64> {
    let mut u = vec![0.0; nunits];
    for f in files {
        for c in chans {
            for &k in f.all.get(*c) {
                u[(f.unit0 + f.m.seg.block_of(k)).min(nunits - 1)] += 1.0;
            }
        }
    }
    u
}

/// Runs the diagnosis.
pub fn diagnose(
    train: &[Dataset],
    validate: &[Dataset],
    nominal: &Params,
    o: &DiagnoseOptions,
) -> Result<Diagnosis, DiagnoseError> {
    if train.is_empty() {
        return Err(DiagnoseError::NoTraining);
    }
    if validate.is_empty() {
        return Err(DiagnoseError::NoValidation);
    }
    let mut tr = prepare(train, nominal, o, 0);
    let mut va = prepare(validate, nominal, o, 0);
    let nunits_t = units(&tr);
    let nunits_v = units(&va);
    let mut notes = Vec::new();
    let checkable = checkability(&[train, validate].concat());
    // Channels with samples in both sets.
    let chans: Vec<Channel> = Channel::ALL
        .into_iter()
        .filter(|c| {
            tr.iter().any(|f| !f.fit.get(*c).is_empty())
                && va.iter().any(|f| !f.all.get(*c).is_empty())
        })
        .collect();
    if chans.is_empty() {
        return Err(DiagnoseError::NothingCheckable);
    }
    let nominal_model = Model::nominal(*nominal);

    // --- plain recalibration, group by group (thermal first: the torque needs its disk model).
    let gs = groups();
    set_noise(&nominal_model, &mut tr);
    let mut recal = nominal_model;
    let mut recal_fits: BTreeMap<Subsystem, lsq::Fit> = BTreeMap::new();
    for g in &gs {
        if !g.channels.iter().any(|c| chans.contains(c)) {
            continue;
        }
        let (m, fit) = fit_group(&recal, g, None, &tr);
        recal = m;
        if let Some(f) = fit {
            recal_fits.insert(g.subsystem, f);
        }
    }
    set_noise(&recal, &mut tr);
    let sigma = set_noise(&recal, &mut va);
    let recalibration: Vec<(String, f64, f64)> = gs
        .iter()
        .flat_map(|g| g.recal.iter())
        .filter_map(|k| {
            Some((
                k.to_string(),
                keys::get(nominal, k)?,
                keys::get(&recal.p, k)?,
            ))
        })
        .collect();

    // Scores of the baselines.
    let sc_nom_v = score(&nominal_model, &va, &chans, nunits_v, false);
    let sc_rec_v = score(&recal, &va, &chans, nunits_v, false);
    let sc_rec_t = score(&recal, &tr, &chans, nunits_t, true);
    let n_val: f64 = chans.iter().map(|c| sc_rec_v.n[c.index()] as f64).sum();
    let u_rec = unit_std(&sc_rec_v, &chans, nunits_v);
    let u_n = unit_n(&va, &chans, nunits_v);
    let s_rec: f64 = u_rec.iter().sum();
    let excess_rec = (s_rec - n_val).max(1e-9);

    // Effective training sample sizes per channel (autocorrelation of the recal residuals).
    let n_eff: Vec<f64> = Channel::ALL
        .iter()
        .map(|c| {
            let mut r = Vec::new();
            for (f, pr) in tr.iter().zip(&sc_rec_t.preds) {
                let y = &pr.y[c.index()];
                if y.is_empty() {
                    continue;
                }
                for &k in f.fit.get(*c) {
                    r.push(candidates::measured(&f.m, *c, k) - y[k]);
                }
            }
            if r.is_empty() {
                0.0
            } else {
                lsq::effective_n(&r)
            }
        })
        .collect();

    // --- every library effect.
    let mut rng = Rng::new(o.seed);
    let mut ranked: Vec<(Ranked, Model, Scores)> = Vec::new();
    for id in EffectId::LIBRARY {
        let sub = fit_group_of(id);
        let Some(g) = gs.iter().find(|g| g.subsystem == sub) else {
            continue;
        };
        if !g.channels.iter().any(|c| chans.contains(c)) {
            continue;
        }
        let (mut model, fit) = fit_group(&recal, g, Some(id), &tr);
        let mut fit_chans: Vec<Channel> = g.channels.clone();
        // A thermal effect changes the disk temperature too: refit the torque recalibration.
        if sub == Subsystem::Thermal {
            if let Some(gq) = gs
                .iter()
                .find(|g| g.subsystem == Subsystem::TorqueCharacteristic)
            {
                let (m2, _) = fit_group(&model, gq, None, &tr);
                model = m2;
                fit_chans.extend(gq.channels.iter().copied());
            }
        }
        fit_chans.retain(|c| chans.contains(c));
        let Some(fit) = fit else { continue };
        // ΔBIC on training over the channels the fit touched.
        let sc_t = score(&model, &tr, &fit_chans, nunits_t, true);
        let mut ll = 0.0;
        let mut neff_sum = 0.0;
        for c in &fit_chans {
            let i = c.index();
            if sc_rec_t.sse[i] > 0.0 && sc_t.sse[i] > 0.0 && n_eff[i] > 0.0 {
                ll += n_eff[i] * (sc_t.sse[i] / sc_rec_t.sse[i]).ln();
                neff_sum += n_eff[i];
            }
        }
        let k = id.params().len() as f64;
        let delta_bic = ll + k * neff_sum.max(2.0).ln();
        // Validation: the share of the recalibrated excess over the noise floor that the
        // effect removes, on the channels it acts on (other channels are the same for every
        // candidate of the group and would only dilute the share).
        let sc_v = score(&model, &va, &chans, nunits_v, false);
        let ug_rec = unit_std(&sc_rec_v, &fit_chans, nunits_v);
        let ug_e = unit_std(&sc_v, &fit_chans, nunits_v);
        let ug_n = unit_n(&va, &fit_chans, nunits_v);
        let (sg_rec, sg_e, sg_n): (f64, f64, f64) =
            (ug_rec.iter().sum(), ug_e.iter().sum(), ug_n.iter().sum());
        let floor = 0.02 * sg_n;
        let share = (sg_rec - sg_e) / (sg_rec - sg_n).max(floor).max(1e-9);
        let ci = stats::bootstrap(nunits_v, o.bootstrap, &mut rng, |idx| {
            let (mut a, mut b, mut nn) = (0.0, 0.0, 0.0);
            for &j in idx {
                a += ug_rec[j];
                b += ug_e[j];
                nn += ug_n[j];
            }
            (a - b) / (a - nn).max(0.02 * nn).max(1e-9)
        });
        let improvement_significant = ci.0 > 0.0;
        // Practical significance: the fitted magnitude must reach a fraction of the smallest
        // documented plausible magnitude (a tiny backlash, for one, merely filters sensor noise).
        let magnitude_ok = id.params().iter().enumerate().all(|(j, ps)| {
            let d_lo = (ps.plausible.0 - ps.nominal).abs();
            let d_hi = (ps.plausible.1 - ps.nominal).abs();
            let smallest = if ps.plausible.0 <= ps.nominal && ps.nominal <= ps.plausible.1 {
                d_lo.max(d_hi) * 0.5
            } else {
                d_lo.min(d_hi)
            };
            (fit.p[j] - ps.nominal).abs() >= o.min_effect_fraction * smallest
        });
        // Physical plausibility: within the documented plausible range widened by its width on
        // each side (a spring that stiffens with temperature, say, is not that effect).
        let plausible_ok = id.params().iter().enumerate().all(|(j, ps)| {
            let w = (ps.plausible.1 - ps.plausible.0).abs();
            fit.p[j] >= ps.plausible.0 - w && fit.p[j] <= ps.plausible.1 + w
        });
        let credited = delta_bic < o.bic_threshold
            && improvement_significant
            && share >= o.min_gap_reduction
            && magnitude_ok
            && plausible_ok;
        let mut parameters = BTreeMap::new();
        let mut parameters_ci95 = BTreeMap::new();
        for (j, ps) in id.params().iter().enumerate() {
            parameters.insert(ps.name.to_string(), fit.p[j]);
            parameters_ci95.insert(ps.name.to_string(), fit.ci95[j]);
        }
        let recalibrated = g
            .recal
            .iter()
            .filter_map(|k| Some((k.to_string(), keys::get(&model.p, k)?)))
            .collect();
        let validation_rmse = chans
            .iter()
            .filter(|c| sc_v.n[c.index()] > 0)
            .map(|c| {
                (
                    c.name().to_string(),
                    (sc_v.sse[c.index()] / sc_v.n[c.index()] as f64).sqrt(),
                )
            })
            .collect();
        let note = if credited {
            "credited".to_string()
        } else {
            let mut why = Vec::new();
            if delta_bic >= o.bic_threshold {
                why.push(format!("ΔBIC {delta_bic:.1} ≥ {}", o.bic_threshold));
            }
            if !improvement_significant {
                why.push("validation improvement not significant".to_string());
            }
            if !plausible_ok {
                why.push("fitted value far outside the plausible range".to_string());
            }
            if !magnitude_ok {
                why.push(format!(
                    "fitted magnitude below {:.0} % of the smallest plausible one",
                    100.0 * o.min_effect_fraction
                ));
            }
            if share < o.min_gap_reduction {
                why.push(format!(
                    "removes {:.1} % < {:.0} % of the validation gap",
                    100.0 * share,
                    100.0 * o.min_gap_reduction
                ));
            }
            why.join("; ")
        };
        ranked.push((
            Ranked {
                effect: id.as_str().to_string(),
                subsystem: id.subsystem().as_str().to_string(),
                parameters,
                parameters_ci95,
                recalibrated,
                validation_rmse,
                validation_score: rms_std(&sc_v, &chans),
                delta_bic,
                gap_explained_pct: 100.0 * share,
                gap_explained_ci95: (100.0 * ci.0, 100.0 * ci.1),
                credited,
                note,
            },
            model,
            sc_v,
        ));
    }
    ranked.sort_by(|a, b| a.0.validation_score.total_cmp(&b.0.validation_score));

    // --- outside the library: black-box discrepancy of the torque characteristic.
    let tq_chans: Vec<Channel> = [Channel::Torque(0), Channel::Torque(1)]
        .into_iter()
        .filter(|c| chans.contains(c))
        .collect();
    let best = ranked.iter().find(|r| r.0.credited);
    let mut blackbox = None;
    let mut outside = false;
    if !tq_chans.is_empty() {
        let design = |files: &[File], sc: &Scores, fit: bool| -> Design {
            let items: Vec<_> = files
                .iter()
                .zip(&sc.preds)
                .filter_map(|(f, pr)| {
                    let disk = pr.disk.as_ref()?;
                    let s = if fit { &f.fit } else { &f.all };
                    let y = &pr.y;
                    Some((
                        &f.m,
                        s.get(Channel::Torque(0)),
                        s.get(Channel::Torque(1)),
                        [
                            y[Channel::Torque(0).index()].clone(),
                            y[Channel::Torque(1).index()].clone(),
                        ],
                        disk,
                        f.unit0,
                        [
                            f.sigma[Channel::Torque(0).index()],
                            f.sigma[Channel::Torque(1).index()],
                        ],
                    ))
                })
                .collect();
            let items_ref: Vec<_> = items
                .iter()
                .map(|(m, a, b, t, d, u, sg)| (*m, *a, *b, t, *d, *u, *sg))
                .collect();
            Design::collect(&recal.p, &items_ref)
        };
        let dt = design(&tr, &sc_rec_t, true);
        let dv = design(&va, &sc_rec_v, false);
        if let Some(bb) = blackbox::check(&dt, &dv, nunits_v, &tq_chans) {
            // Torque-channel excess (the design is standardized with each file's noise floor).
            let n_tq = dv.len() as f64;
            let ex_tq = (bb.sse_before - n_tq).max(0.02 * n_tq).max(1e-9);
            let share_bb = (bb.sse_before - bb.sse_after) / ex_tq;
            let share_best = best
                .map(|b| {
                    let s: f64 = tq_chans.iter().map(|c| b.2.std_sse[c.index()]).sum();
                    (bb.sse_before - s) / ex_tq
                })
                .unwrap_or(0.0);
            // Bootstrap: is the black box's gain over the best effect real?
            let u_bb = &bb.unit_sse_after;
            let u_best: Vec<f64> = match best {
                Some(b) => (0..nunits_v)
                    .map(|j| tq_chans.iter().map(|c| b.2.std_unit[c.index()][j]).sum())
                    .collect(),
                None => (0..nunits_v)
                    .map(|j| {
                        tq_chans
                            .iter()
                            .map(|c| sc_rec_v.std_unit[c.index()][j])
                            .sum()
                    })
                    .collect(),
            };
            let ci = stats::bootstrap(nunits_v, o.bootstrap, &mut rng, |idx| {
                idx.iter().map(|&j| u_best[j] - u_bb[j]).sum::<f64>()
            });
            let significant_gap = ex_tq / n_tq > 0.05;
            outside = significant_gap
                && share_bb >= o.outside_min_share
                && share_bb - share_best >= o.outside_margin
                && ci.0 > 0.0;
            notes.push(format!(
                "black box (torque characteristic): explains {:.1} % of the validation torque \
                 excess, best credited effect {:.1} %; gain over it significant: {}",
                100.0 * share_bb,
                100.0 * share_best,
                ci.0 > 0.0
            ));
            blackbox = Some(bb);
        }
    }

    // --- verdict.
    let excess_share = excess_rec / n_val.max(1.0);
    let remains = {
        let ci = stats::bootstrap(nunits_v, o.bootstrap, &mut rng, |idx| {
            idx.iter().map(|&j| u_rec[j] - u_n[j]).sum::<f64>()
        });
        ci.0 > 0.0 && excess_share > 0.05
    };
    let (effect, subsystem, model_after, explanation) = if outside {
        (
            "outside_library".to_string(),
            Subsystem::TorqueCharacteristic.as_str().to_string(),
            recal,
            "a black-box discrepancy of the torque characteristic explains far more of the \
             validation gap than any library effect"
                .to_string(),
        )
    } else if let Some(b) = best {
        (
            b.0.effect.clone(),
            b.0.subsystem.clone(),
            b.1,
            format!(
                "{} removes {:.1} % of the recalibrated validation gap (ΔBIC {:.1})",
                b.0.effect, b.0.gap_explained_pct, b.0.delta_bic
            ),
        )
    } else if remains {
        (
            "none".to_string(),
            "none".to_string(),
            recal,
            "a gap remains after recalibration but no library effect explains it significantly \
             and the black box does not either"
                .to_string(),
        )
    } else {
        (
            "none".to_string(),
            "none".to_string(),
            recal,
            "nothing significant remains after recalibration".to_string(),
        )
    };
    if !remains && effect == "none" {
        notes.push(format!(
            "recalibrated validation excess over the noise floor: {:.1} % of the expected",
            100.0 * excess_share
        ));
    }
    // Ambiguity: credited effects not significantly worse than the best.
    let mut ambiguous_with = Vec::new();
    if let Some(b) = best.filter(|_| !outside) {
        let u_b = unit_std(&b.2, &chans, nunits_v);
        for r in ranked
            .iter()
            .filter(|r| r.0.credited && r.0.effect != b.0.effect)
        {
            let u_r = unit_std(&r.2, &chans, nunits_v);
            let ci = stats::bootstrap(nunits_v, o.bootstrap, &mut rng, |idx| {
                idx.iter().map(|&j| u_r[j] - u_b[j]).sum::<f64>()
            });
            if ci.0 <= 0.0 {
                ambiguous_with.push(r.0.effect.clone());
            }
        }
    }
    // Subsystems in order of evidence: the verdict's, then by residual excess.
    let where_ = where_::locate(
        &recal,
        &va.iter().map(|f| &f.m).collect::<Vec<_>>(),
        &va.iter().map(|f| &f.all).collect::<Vec<_>>(),
        &sc_rec_v.preds,
        &va.iter().map(|f| f.sigma.as_slice()).collect::<Vec<_>>(),
        &chans,
        o.fdr_q,
    );
    let mut subsystems = Vec::new();
    if subsystem != "none" {
        subsystems.push(subsystem.clone());
    }
    for s in &where_.residual_subsystems {
        if s.significant && !subsystems.contains(&s.subsystem) {
            subsystems.push(s.subsystem.clone());
        }
    }

    // --- how far.
    let sc_after = score(&model_after, &va, &chans, nunits_v, false);
    let mut where_ = where_;
    where_.bias_maps.push(where_::bias_map(
        &va.iter().map(|f| &f.m).collect::<Vec<_>>(),
        &va.iter().map(|f| &f.all).collect::<Vec<_>>(),
        &sc_after.preds,
        "after",
        o.fdr_q,
    ));
    let mut eq = Vec::new();
    for c in &chans {
        let i = c.index();
        let n = sc_nom_v.n[i];
        if n == 0 {
            continue;
        }
        let r = |s: &Scores| (s.sse[i] / s.n[i].max(1) as f64).sqrt();
        let (rn, rr, ra) = (r(&sc_nom_v), r(&sc_rec_v), r(&sc_after));
        let var = {
            let mut sum = 0.0;
            let mut sq = 0.0;
            let mut cnt = 0.0;
            for f in &va {
                for &k in f.all.get(*c) {
                    let y = candidates::measured(&f.m, *c, k);
                    sum += y;
                    sq += y * y;
                    cnt += 1.0;
                }
            }
            (sq / cnt - (sum / cnt).powi(2)).max(1e-30)
        };
        let fitp = |rm: f64| 100.0 * (1.0 - rm / var.sqrt());
        let un = &sc_nom_v.unit_sse[i];
        let ua = &sc_after.unit_sse[i];
        let ci = stats::bootstrap(nunits_v, o.bootstrap, &mut rng, |idx| {
            let (a, b) = idx
                .iter()
                .fold((0.0, 0.0), |s, &j| (s.0 + un[j], s.1 + ua[j]));
            if a > 0.0 {
                100.0 * (1.0 - (b / a).sqrt())
            } else {
                f64::NAN
            }
        });
        // Gap above the noise floor of each record: √max(mean standardized square − 1, 0).
        let zn = sc_nom_v.std_sse[i] / n as f64;
        let za = sc_after.std_sse[i] / sc_after.n[i].max(1) as f64;
        let gap_n = (zn - 1.0).max(0.0).sqrt();
        let gap_a = (za - 1.0).max(0.0).sqrt();
        eq.push(OutputGap {
            output: c.name().to_string(),
            subsystem: c.subsystem().as_str().to_string(),
            n,
            noise: sigma[i],
            rmse_nominal: rn,
            rmse_recalibrated: rr,
            rmse_after: ra,
            fit_pct_nominal: fitp(rn),
            fit_pct_after: fitp(ra),
            reduction_pct: 100.0 * (1.0 - ra / rn.max(1e-300)),
            reduction_ci95: ci,
            gap_reduction_pct: if gap_n > 0.0 {
                100.0 * (1.0 - gap_a / gap_n)
            } else {
                0.0
            },
        });
    }
    // Main output: of the verdict's subsystem (or of the largest residual), the output whose
    // nominal gap above noise is largest.
    let main_sub = if subsystem != "none" {
        subsystem.clone()
    } else {
        where_
            .residual_subsystems
            .first()
            .map(|s| s.subsystem.clone())
            .unwrap_or_else(|| "torque_characteristic".into())
    };
    let main_sub = if effect == EffectId::ActuatorBacklash.as_str() {
        Subsystem::TorqueCharacteristic.as_str().to_string()
    } else {
        main_sub
    };
    let main = eq
        .iter()
        .filter(|g| g.subsystem == main_sub)
        .max_by(|a, b| {
            let ga = a.rmse_nominal.powi(2) - a.noise.powi(2);
            let gb = b.rmse_nominal.powi(2) - b.noise.powi(2);
            ga.total_cmp(&gb)
        })
        .or_else(|| eq.first())
        .cloned();
    let replay_error = replay_gaps(&nominal_model, &model_after, &va);
    let how_far = match &main {
        Some(g) => HowFar {
            output: g.output.clone(),
            rmse_before: g.rmse_nominal,
            rmse_recalibrated: g.rmse_recalibrated,
            rmse_after: g.rmse_after,
            reduction_pct: g.reduction_pct,
            reduction_ci95: g.reduction_ci95,
            gap_reduction_pct: g.gap_reduction_pct,
            equation_error: eq.clone(),
            replay_error,
        },
        None => HowFar {
            output: String::new(),
            rmse_before: f64::NAN,
            rmse_recalibrated: f64::NAN,
            rmse_after: f64::NAN,
            reduction_pct: f64::NAN,
            reduction_ci95: (f64::NAN, f64::NAN),
            gap_reduction_pct: f64::NAN,
            equation_error: eq.clone(),
            replay_error,
        },
    };
    // Traces of the main output on the first validation file.
    let mut traces = Vec::new();
    if let (Some(g), Some(f)) = (&main, va.first()) {
        if let Some(c) = Channel::ALL.iter().find(|c| c.name() == g.output) {
            let pn = candidates::predict(&nominal_model, &f.m, &f.all, &[*c]);
            let pa = candidates::predict(&model_after, &f.m, &f.all, &[*c]);
            let idx = f.all.get(*c);
            traces.push(Trace {
                file: f.m.source.clone(),
                output: g.output.clone(),
                t: idx.iter().map(|&k| f.m.time[k]).collect(),
                measured: idx
                    .iter()
                    .map(|&k| candidates::measured(&f.m, *c, k))
                    .collect(),
                nominal: idx.iter().map(|&k| pn.y[c.index()][k]).collect(),
                after: idx.iter().map(|&k| pa.y[c.index()][k]).collect(),
            });
        }
    }
    let calibrated = Some((model_after.p, model_after.set));
    let outside_library_depends_on = if outside {
        blackbox
            .as_ref()
            .map(|b| b.depends_on.iter().map(|(n, _)| n.clone()).collect())
            .unwrap_or_default()
    } else {
        Vec::new()
    };
    let findings = legacy_findings(&effect, &subsystem, &outside_library_depends_on);
    Ok(Diagnosis {
        train_files: train.iter().map(|d| d.source.clone()).collect(),
        validate_files: validate.iter().map(|d| d.source.clone()).collect(),
        separability: separability(&checkable),
        checkable,
        where_,
        verdict: Verdict {
            subsystem,
            subsystems,
            effect,
            ranking: ranked.into_iter().map(|r| r.0).collect(),
            ambiguous_with,
            outside_library_depends_on,
            explanation,
            findings,
        },
        how_far,
        recalibration,
        blackbox,
        notes,
        calibrated,
        traces,
    })
}

/// Findings from the single-effect verdict (transitional).
fn legacy_findings(effect: &str, subsystem: &str, depends_on: &[String]) -> Vec<Finding> {
    use super::class::ClassId;
    use super::finding::{ClassFinding, OutsideFinding};
    if effect == "outside_library" {
        return vec![Finding::OutsideLibrary(OutsideFinding {
            subsystem: Subsystem::parse(subsystem).unwrap_or(Subsystem::TorqueCharacteristic),
            excess: f64::NAN,
            depends_on: depends_on.to_vec(),
            time_structure: String::new(),
        })];
    }
    match EffectId::parse(effect).and_then(ClassId::of_effect) {
        Some(c) => vec![Finding::Class(ClassFinding {
            class: c,
            subsystem: c.subsystem(),
            variable: c.variable(),
            ambiguous_with: Vec::new(),
            share_pct: f64::NAN,
            magnitude: f64::NAN,
            magnitude_ci95: (f64::NAN, f64::NAN),
            unit: "",
            range_warning: None,
            shape: Vec::new(),
            parameters: BTreeMap::new(),
        })],
        None => vec![Finding::Nothing],
    }
}

/// Free-running replay RMSE of torque and temperatures, nominal vs after.
fn replay_gaps(nominal: &Model, after: &Model, files: &[File]) -> Vec<ReplayGap> {
    let names = ["T_c1_Nm", "T_c2_Nm", "th_pp1_C", "th_pp2_C", "th_cd_C"];
    let mut se = [[0.0f64; 5]; 2];
    let mut n = [0usize; 5];
    for f in files {
        for (j, model) in [nominal, after].iter().enumerate() {
            let h = candidates::SetHooks(model.set);
            let r = replay::full_replay(&model.p, &h, &f.m);
            for k in 0..f.m.n {
                if !f.m.valid[k] {
                    continue;
                }
                let th = &r.thermal[k];
                let pred = [r.torque[0][k], r.torque[1][k], th.pp1, th.pp2, th.cd];
                let meas = [
                    f.m.torque[0][k],
                    f.m.torque[1][k],
                    f.m.pp[0][k],
                    f.m.pp[1][k],
                    f.m.cd[k],
                ];
                for q in 0..5 {
                    se[j][q] += (meas[q] - pred[q]).powi(2);
                    if j == 0 {
                        n[q] += 1;
                    }
                }
            }
        }
    }
    (0..5)
        .filter(|&q| n[q] > 0)
        .map(|q| ReplayGap {
            output: names[q].to_string(),
            rmse_nominal: (se[0][q] / n[q] as f64).sqrt(),
            rmse_after: (se[1][q] / n[q] as f64).sqrt(),
        })
        .collect()
}

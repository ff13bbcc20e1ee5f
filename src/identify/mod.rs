//! Parameter identification as the paper tuned its models (Sects. 3.3 and 4.2), on bench
//! records with separate identification (training) and validation files:
//!
//! 1. λ0 (kiss point at room temperature, (9)) and x_to,max from the first engagement of the
//!    identification set, which happens at room temperature (x_to,max only when the profile
//!    reaches it — otherwise it is reported as not identifiable and kept).
//! 2. The convective thermal terms α2 (pressure plates) and α8 (central disk) of (16) by linear
//!    least squares on the cooling phase (both clutches open, so (16a) and (16e) reduce to
//!    θ̇ = α(θ_h − θ)), in integral form over windows: Δθ = α·∫(θ_h − θ)dt (no differentiation of
//!    quantised temperatures).
//! 3. The remaining thermal terms (α1, α3–α7, α9) by nonlinear least squares: the model (16)
//!    replayed from the measured friction power T_c·ω_fc and housing temperature against the
//!    measured plate and central-disk temperatures.
//! 4. λ1, λ2 (and λ0 refined) of (9) by nonlinear least squares over the whole acquisition:
//!    measured torque against (13) at the measured x_to and slip and the clutch-disk temperature
//!    estimated from the measured temperatures ([`replay::disk_estimate`]).
//!    Steps 3–4 are repeated once (the contact flag β of (16) depends on the kiss point).
//!
//! The paper used a genetic algorithm for 3–4; a bounded Levenberg–Marquardt reaches the same
//! least-squares minimum on these smooth problems and gives covariance-based 95 % intervals.
//! Validation: fit % = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖) of every output on the validation files, for the
//! free-running replay (torque and temperatures from the measured inputs only) and for the
//! per-subsystem replays.

use crate::gap::eval::replay;
use crate::gap::fit::lsq::{self, LmOptions, ParamSpec};
use crate::gap::model::keys::ParamKey;
use crate::gap::record::measured::Measured;
use crate::model::params::{Params, ParamsError};
use crate::model::powertrain::{Hooks, Nominal};
use crate::records::dataset::Dataset;
use crate::records::events::{EventKind, SegmentOptions};

/// Options of the identification.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentifyOptions {
    pub seg: SegmentOptions,
    /// Every how many samples a temperature residual is taken (temperatures are slow).
    pub thermal_decimate: usize,
    /// Window of the cooling-phase regression (s).
    pub cooling_window_s: f64,
    /// Thermal parameters of step 3: those that act on the measured plate and central-disk
    /// temperatures.
    pub thermal_keys: Vec<ParamKey>,
    /// Thermal parameters that act only on the (unmeasured) clutch-disk temperature: the torque
    /// is what determines them, in step 5.
    pub disk_keys: Vec<ParamKey>,
    /// Repetitions of steps 3–4.
    pub outer_iterations: usize,
    /// Run step 5 (joint refinement of thermal and torque terms).
    pub joint: bool,
    /// Widen step 5's intervals by split-half refits.
    pub split_half: bool,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        IdentifyOptions {
            seg: SegmentOptions::default(),
            thermal_decimate: 10,
            cooling_window_s: 5.0,
            thermal_keys: vec![
                ParamKey::Alpha1,
                ParamKey::Alpha3,
                ParamKey::Alpha5,
                ParamKey::Alpha9,
            ],
            disk_keys: vec![ParamKey::Alpha4, ParamKey::Alpha6, ParamKey::Alpha7],
            outer_iterations: 2,
            joint: true,
            split_half: true,
        }
    }
}

/// Errors of the identification.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    #[error("no identification (training) file given")]
    NoTraining,
    #[error("{file}: no engagement found (no clutch torque above {torque_on} N·m)")]
    NoEngagement { file: String, torque_on: f64 },
    #[error("the fitted parameters are inconsistent: {0}")]
    Params(#[from] ParamsError),
}

/// One identified parameter.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Estimate {
    /// `table.key` in the parameter file.
    pub key: ParamKey,
    pub unit: String,
    pub initial: f64,
    pub value: f64,
    pub std_err: f64,
    pub ci95: (f64, f64),
    /// Which step of the procedure fitted it.
    pub step: String,
    /// False when the data cannot determine it (the value is then the initial one).
    pub identifiable: bool,
}

/// Fit of one output on one file.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct OutputFit {
    pub file: String,
    /// Output name as in the CSV columns (e.g. `T_c1_Nm`, `th_cd_C`, `x_to1_mm`).
    pub output: String,
    /// `replay` (free-running model from the measured inputs), `thermal_replay` (thermal model
    /// from the measured friction power), `equation` (torque at measured x_to, slip, temperatures)
    /// or `actuator_replay`.
    pub mode: String,
    pub n: usize,
    pub rmse: f64,
    pub nrmse: f64,
    /// 100·(1 − NRMSE); NaN (`null` in JSON) for an output the experiment does not excite
    /// (variance below 25 residual variances, e.g. a clutch never engaged).
    pub fit_pct: f64,
}

/// Result of [`identify`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Identification {
    /// The identified parameter set (the others as given).
    pub params: Params,
    pub estimates: Vec<Estimate>,
    pub training: Vec<OutputFit>,
    pub validation: Vec<OutputFit>,
    pub notes: Vec<String>,
}

/// RMSE, NRMSE and fit % of a prediction over the samples where `mask` holds.
pub fn fit_stats(y: &[f64], yhat: &[f64], mask: &[bool]) -> (usize, f64, f64, f64) {
    let mut n = 0usize;
    let mut sy = 0.0;
    for k in 0..y.len() {
        if mask[k] && y[k].is_finite() && yhat[k].is_finite() {
            n += 1;
            sy += y[k];
        }
    }
    if n == 0 {
        return (0, f64::NAN, f64::NAN, f64::NAN);
    }
    let mean = sy / n as f64;
    let (mut se, mut sv) = (0.0, 0.0);
    for k in 0..y.len() {
        if mask[k] && y[k].is_finite() && yhat[k].is_finite() {
            se += (y[k] - yhat[k]).powi(2);
            sv += (y[k] - mean).powi(2);
        }
    }
    let rmse = (se / n as f64).sqrt();
    // An output that does not move beyond its residual (a clutch never engaged) has no fit %.
    let excited = sv / n as f64 > 25.0 * rmse * rmse;
    let nrmse = if sv > 0.0 && excited {
        (se / sv).sqrt()
    } else {
        f64::NAN
    };
    (n, rmse, nrmse, 100.0 * (1.0 - nrmse))
}

fn output_fit(
    file: &str,
    output: &str,
    mode: &str,
    y: &[f64],
    yhat: &[f64],
    mask: &[bool],
) -> OutputFit {
    let (n, rmse, nrmse, fit_pct) = fit_stats(y, yhat, mask);
    OutputFit {
        file: file.to_string(),
        output: output.to_string(),
        mode: mode.to_string(),
        n,
        rmse,
        nrmse,
        fit_pct,
    }
}

/// Fit % of every output of a set of files with a given model (parameters + hooks).
pub fn output_fits(p: &Params, h: &dyn Hooks, ms: &[Measured]) -> Vec<OutputFit> {
    let mut out = Vec::new();
    for m in ms {
        let f = &m.source;
        let fr = replay::full_replay(p, h, m);
        let tr = replay::thermal_replay(p, h, m);
        let th_names = ["th_pp1_C", "th_pp2_C", "th_cd_C"];
        let meas = [&m.pp[0], &m.pp[1], &m.cd];
        for j in 0..3 {
            let get = |s: &crate::model::thermal::Thermal5State| [s.pp1, s.pp2, s.cd][j];
            let yr: Vec<f64> = fr.thermal.iter().map(get).collect();
            let yt: Vec<f64> = tr.iter().map(get).collect();
            out.push(output_fit(f, th_names[j], "replay", meas[j], &yr, &m.valid));
            out.push(output_fit(
                f,
                th_names[j],
                "thermal_replay",
                meas[j],
                &yt,
                &m.valid,
            ));
        }
        let disk = replay::disk_estimate(p, h, m);
        for i in 0..2 {
            let name = ["T_c1_Nm", "T_c2_Nm"][i];
            out.push(output_fit(
                f,
                name,
                "replay",
                &m.torque[i],
                &fr.torque[i],
                &m.valid,
            ));
            let eq: Vec<f64> = (0..m.n)
                .map(|k| replay::torque_eq(p, h, m, &disk, i, k))
                .collect();
            out.push(output_fit(f, name, "equation", &m.torque[i], &eq, &m.valid));
        }
        for i in 0..2 {
            if let Some(xr) = &m.x_req[i] {
                let xs = replay::actuator_replay(&p.actuator, xr, m.x[i][0], m.dt);
                out.push(output_fit(
                    f,
                    ["x_to1_mm", "x_to2_mm"][i],
                    "actuator_replay",
                    &m.x[i],
                    &xs,
                    &m.valid,
                ));
            }
        }
    }
    out
}

/// Builds a parameter set from a base and values for `keys`; `None` when inconsistent.
fn with_values(base: &Params, keys: &[ParamKey], v: &[f64]) -> Option<Params> {
    let mut p = *base;
    for (k, x) in keys.iter().zip(v) {
        k.set(&mut p, *x);
    }
    p.clutch.validate().ok()?;
    Some(p)
}

/// Solver specifications: start at `base`, bounds from the parameter file's ranges; the thermal
/// rates and gains (positive, known to an order of magnitude) are solved in log space within a
/// factor 30 of the user's `initial` value.
fn specs_for(base: &Params, initial: &Params, keys: &[ParamKey]) -> Vec<ParamSpec> {
    keys.iter()
        .map(|k| {
            let v = k.get(base);
            let (lo, hi) = k.range();
            if k.is_thermal() {
                let v0 = k.get(initial).abs().max(1e-9);
                let (lo, hi) = (lo.max(v0 / 30.0), hi.min(v0 * 30.0));
                ParamSpec::new(k.as_str(), v, lo, hi, k.scale()).log()
            } else {
                ParamSpec::new(k.as_str(), v, lo, hi, k.scale())
            }
        })
        .collect()
}

/// The estimates of an identification fit, whose parameters are keys ([`specs_for`]).
fn estimates_from(fit: &lsq::Fit, initial: &Params, step: &str) -> Vec<Estimate> {
    fit.names
        .iter()
        .enumerate()
        .filter_map(|(j, name)| Some((j, ParamKey::parse(name)?)))
        .map(|(j, k)| Estimate {
            key: k,
            unit: k.unit().to_string(),
            initial: k.get(initial),
            value: fit.p[j],
            std_err: fit.std_err[j],
            ci95: fit.ci95[j],
            step: step.to_string(),
            identifiable: fit.std_err[j].is_finite(),
        })
        .collect()
}

/// Step 1: λ0 and x_to,max from the first engagement. Returns the fit and whether x_to,max was
/// reached by the profile.
fn first_engagement(
    p: &Params,
    m: &Measured,
    opts: &IdentifyOptions,
) -> Result<(lsq::Fit, bool, String), IdentifyError> {
    let first = m
        .seg
        .events
        .iter()
        .filter(|e| e.kind == EventKind::Engagement)
        .min_by_key(|e| e.start)
        .ok_or_else(|| IdentifyError::NoEngagement {
            file: m.source.clone(),
            torque_on: opts.seg.torque_on,
        })?;
    let i = first.clutch.unwrap_or(0);
    let lead = (0.5 / m.dt) as usize;
    let lo = first.start.saturating_sub(lead);
    let hi = (first.end + lead).min(m.n);
    let idx: Vec<usize> = m.torque_idx[i]
        .iter()
        .copied()
        .filter(|&k| k >= lo && k < hi)
        .collect();
    let disk = replay::disk_estimate(p, &Nominal, m);
    let x_peak = idx
        .iter()
        .map(|&k| m.x[i][k])
        .fold(f64::NEG_INFINITY, f64::max);
    let reaches_max = x_peak > p.clutch.x_to_max_mm - 0.05;
    let mut keys_v: Vec<ParamKey> = vec![ParamKey::XIsp0];
    if reaches_max {
        keys_v.push(ParamKey::XToMax);
    }
    let mut specs = specs_for(p, p, &keys_v);
    specs[0].hi = specs[0].hi.min(p.clutch.x_to_max_mm - 0.2);
    let mut f = |v: &[f64], r: &mut [f64]| match with_values(p, &keys_v, v) {
        Some(q) => {
            for (j, &k) in idx.iter().enumerate() {
                r[j] = m.torque[i][k] - replay::torque_eq(&q, &Nominal, m, &disk, i, k);
            }
        }
        None => r.iter_mut().for_each(|x| *x = 1e6),
    };
    let fit = lsq::levenberg_marquardt(&mut f, idx.len(), &specs, LmOptions::default());
    let note = format!(
        "step 1: first engagement of clutch {} in {} at t = {:.2} s, θ ≈ {:.1} °C, peak x_to {:.3} mm{}",
        i + 1,
        m.source,
        m.time[first.start],
        first.theta_start,
        x_peak,
        if reaches_max {
            String::new()
        } else {
            format!(
                " < x_to,max = {} mm: x_to,max is not identifiable from this profile and is kept",
                p.clutch.x_to_max_mm
            )
        }
    );
    Ok((fit, reaches_max, note))
}

/// Cluster id (global engagement block) of sample k of file `f`.
fn block_ids(ms: &[Measured]) -> Vec<usize> {
    let mut off = Vec::with_capacity(ms.len());
    let mut o = 0;
    for m in ms {
        off.push(o);
        o += m.seg.blocks.len().max(1);
    }
    off
}

/// Step 2: α2 and α8 by linear least squares on the cooling phases.
fn cooling_fit(
    ms: &[Measured],
    opts: &IdentifyOptions,
) -> (Option<lsq::LinearFit>, Option<lsq::LinearFit>, usize) {
    let (mut xp, mut yp, mut xc, mut yc) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut phases = 0;
    for m in ms {
        let w = (opts.cooling_window_s / m.dt).round().max(2.0) as usize;
        for e in m.seg.events.iter().filter(|e| e.kind == EventKind::Cooling) {
            phases += 1;
            // Skip the first seconds (contact may still be releasing).
            let start = e.start + (2.0 / m.dt) as usize;
            let mut k = start;
            while k + w < e.end {
                if (k..=k + w).all(|j| m.valid[j]) {
                    let integ = |v: &[f64], factor: f64| -> f64 {
                        (k..k + w)
                            .map(|j| {
                                0.5 * factor * ((m.th[j] - v[j]) + (m.th[j + 1] - v[j + 1])) * m.dt
                            })
                            .sum()
                    };
                    for i in 0..2 {
                        xp.push(integ(&m.pp[i], 1.0));
                        yp.push(m.pp[i][k + w] - m.pp[i][k]);
                    }
                    xc.push(integ(&m.cd, 2.0));
                    yc.push(m.cd[k + w] - m.cd[k]);
                }
                k += w;
            }
        }
    }
    // Windows where the temperature is within a degree of the housing carry no information.
    let keep = |x: &[f64], y: &[f64]| -> (Vec<f64>, Vec<f64>) {
        x.iter()
            .zip(y)
            .filter(|(a, _)| a.abs() > 1e-3)
            .map(|(a, b)| (*a, *b))
            .unzip()
    };
    let (xp, yp) = keep(&xp, &yp);
    let (xc, yc) = keep(&xc, &yc);
    (
        lsq::linear_lsq(&xp, &yp, 1),
        lsq::linear_lsq(&xc, &yc, 1),
        phases,
    )
}

/// Every `dec`-th sample of a record that is valid: the temperature samples of the thermal fits.
fn valid_samples(m: &Measured, dec: usize) -> impl Iterator<Item = usize> + '_ {
    (0..m.n).step_by(dec.max(1)).filter(|&k| m.valid[k])
}

fn thermal_samples(ms: &[Measured], dec: usize) -> Vec<Vec<usize>> {
    ms.iter().map(|m| valid_samples(m, dec).collect()).collect()
}

/// Step 3: thermal NLS on the plate and central-disk temperatures.
fn thermal_fit(
    p: &Params,
    initial: &Params,
    ms: &[Measured],
    keys_v: &[ParamKey],
    dec: usize,
) -> lsq::Fit {
    let idx = thermal_samples(ms, dec);
    let n: usize = idx.iter().map(|v| 3 * v.len()).sum();
    let off = block_ids(ms);
    let clusters: Vec<usize> = ms
        .iter()
        .zip(&idx)
        .zip(&off)
        .flat_map(|((m, ix), o)| ix.iter().flat_map(move |&k| [o + m.seg.block_of(k); 3]))
        .collect();
    let specs = specs_for(p, initial, keys_v);
    let mut f = |v: &[f64], r: &mut [f64]| match with_values(p, keys_v, v) {
        Some(q) => {
            let mut j = 0;
            for (m, ix) in ms.iter().zip(&idx) {
                let tr = replay::thermal_replay(&q, &Nominal, m);
                for &k in ix {
                    r[j] = m.pp[0][k] - tr[k].pp1;
                    r[j + 1] = m.pp[1][k] - tr[k].pp2;
                    r[j + 2] = m.cd[k] - tr[k].cd;
                    j += 3;
                }
            }
        }
        None => r.iter_mut().for_each(|x| *x = 1e6),
    };
    lsq::levenberg_marquardt_clustered(&mut f, n, &specs, LmOptions::default(), Some(&clusters))
}

/// Step 4: λ's by NLS on the torque over the whole acquisition.
fn torque_fit(p: &Params, initial: &Params, ms: &[Measured], keys_v: &[ParamKey]) -> lsq::Fit {
    let disks: Vec<[Vec<f64>; 2]> = ms
        .iter()
        .map(|m| replay::disk_estimate(p, &Nominal, m))
        .collect();
    let n: usize = ms
        .iter()
        .map(|m| m.torque_idx[0].len() + m.torque_idx[1].len())
        .sum();
    let off = block_ids(ms);
    let clusters: Vec<usize> = ms
        .iter()
        .zip(&off)
        .flat_map(|(m, o)| {
            (0..2).flat_map(move |i| m.torque_idx[i].iter().map(move |&k| o + m.seg.block_of(k)))
        })
        .collect();
    let specs = specs_for(p, initial, keys_v);
    let mut f = |v: &[f64], r: &mut [f64]| match with_values(p, keys_v, v) {
        Some(q) => {
            let mut j = 0;
            for (m, disk) in ms.iter().zip(&disks) {
                for i in 0..2 {
                    for &k in m.torque_idx[i].iter() {
                        r[j] = m.torque[i][k] - replay::torque_eq(&q, &Nominal, m, disk, i, k);
                        j += 1;
                    }
                }
            }
        }
        None => r.iter_mut().for_each(|x| *x = 1e6),
    };
    lsq::levenberg_marquardt_clustered(&mut f, n, &specs, LmOptions::default(), Some(&clusters))
}

/// Step 5: joint refinement of the thermal and torque parameters on temperatures and torque
/// together, each channel weighted by the inverse of its residual RMS after steps 3–4. The disk
/// temperature is not measured: the torque is what pins the disk terms (α4–α7) down, and the
/// temperatures pin the plate and central-disk terms.
#[allow(clippy::too_many_arguments)]
fn joint_fit(
    p: &Params,
    initial: &Params,
    ms: &[Measured],
    keys_v: &[ParamKey],
    dec: usize,
    sigma_temp: f64,
    sigma_torque: f64,
    parity: Option<usize>,
    max_iter: usize,
) -> lsq::Fit {
    let idx = thermal_samples(ms, dec);
    let n: usize = idx.iter().map(|v| 3 * v.len()).sum::<usize>()
        + ms.iter()
            .map(|m| m.torque_idx[0].len() + m.torque_idx[1].len())
            .sum::<usize>();
    let off = block_ids(ms);
    let mut clusters = Vec::with_capacity(n);
    for ((m, ix), o) in ms.iter().zip(&idx).zip(&off) {
        for &k in ix {
            clusters.extend([o + m.seg.block_of(k); 3]);
        }
        for i in 0..2 {
            clusters.extend(m.torque_idx[i].iter().map(|&k| o + m.seg.block_of(k)));
        }
    }
    let specs = specs_for(p, initial, keys_v);
    let (wt, wq) = (1.0 / sigma_temp.max(1e-3), 1.0 / sigma_torque.max(1e-3));
    // A split-half refit keeps only the residuals of every other block.
    let keep: Vec<f64> = clusters
        .iter()
        .map(|c| match parity {
            Some(par) if c % 2 != par => 0.0,
            _ => 1.0,
        })
        .collect();
    let mut f = |v: &[f64], r: &mut [f64]| match with_values(p, keys_v, v) {
        Some(q) => {
            let mut j = 0;
            for (m, ix) in ms.iter().zip(&idx) {
                let tr = replay::thermal_replay(&q, &Nominal, m);
                for &k in ix {
                    r[j] = wt * keep[j] * (m.pp[0][k] - tr[k].pp1);
                    r[j + 1] = wt * keep[j + 1] * (m.pp[1][k] - tr[k].pp2);
                    r[j + 2] = wt * keep[j + 2] * (m.cd[k] - tr[k].cd);
                    j += 3;
                }
                let disk = replay::disk_estimate(&q, &Nominal, m);
                for i in 0..2 {
                    for &k in m.torque_idx[i].iter() {
                        r[j] = wq
                            * keep[j]
                            * (m.torque[i][k] - replay::torque_eq(&q, &Nominal, m, &disk, i, k));
                        j += 1;
                    }
                }
            }
        }
        None => r.iter_mut().for_each(|x| *x = 1e6),
    };
    lsq::levenberg_marquardt_clustered(
        &mut f,
        n,
        &specs,
        LmOptions {
            max_iter,
            central: true,
            ..LmOptions::default()
        },
        Some(&clusters),
    )
}

/// Runs the paper's tuning procedure from `initial` on the identification files and reports the
/// validation fit on `validate`.
pub fn identify(
    train: &[Dataset],
    validate: &[Dataset],
    initial: &Params,
    opts: &IdentifyOptions,
) -> Result<Identification, IdentifyError> {
    if train.is_empty() {
        return Err(IdentifyError::NoTraining);
    }
    let ms = Measured::sequence(train, initial, &opts.seg);
    let mut notes = Vec::new();
    let mut p = *initial;

    // 1. λ0 and x_to,max.
    let (fit1, reaches_max, note) = first_engagement(&p, &ms[0], opts)?;
    notes.push(note);
    p.clutch.x_isp0_mm = fit1.p[0];
    if reaches_max {
        p.clutch.x_to_max_mm = fit1.p[1];
    }
    let step1 = estimates_from(&fit1, initial, "1: first engagement");

    // 2. Convective terms on the cooling phase.
    let (step2, thermal_keys) = cooling_step(&mut p, initial, &ms, opts, &mut notes);

    // 3–4, repeated.
    let torque_keys = torque_keys(reaches_max);
    let (fit3, fit4) =
        thermal_and_torque_fits(&mut p, initial, &ms, &thermal_keys, &torque_keys, opts);
    // 5. Joint refinement.
    let fit5 = match (&fit3, &fit4) {
        (Some(f3), Some(f4)) if opts.joint => {
            let keys5: Vec<ParamKey> = thermal_keys
                .iter()
                .chain(&opts.disk_keys)
                .chain(&torque_keys)
                .copied()
                .collect();
            let sigmas = (f3.rms(), f4.rms());
            Some(joint_refinement(
                &mut p, initial, &ms, &keys5, sigmas, opts, &mut notes,
            ))
        }
        _ => None,
    };
    // Step 1's λ0 (and x_to,max) are the start values that step 4 refines: both are reported.
    let mut estimates: Vec<Estimate> = step1;
    estimates.extend(step2);
    for (fit, step) in [
        (&fit3, "3: thermal NLS (θ_pp, θ_cd)"),
        (&fit4, "4: torque NLS (whole acquisition)"),
        (&fit5, "5: joint (temperatures + torque)"),
    ] {
        if let Some(f) = fit {
            estimates.extend(estimates_from(f, initial, step));
        }
    }
    p.validate()?;
    let training = output_fits(&p, &Nominal, &ms);
    let vs = Measured::sequence(validate, &p, &opts.seg);
    let validation = output_fits(&p, &Nominal, &vs);
    Ok(Identification {
        params: p,
        estimates,
        training,
        validation,
        notes,
    })
}

/// Step 2: the convective terms α2 and α8 fitted on the cooling phases and set in `p`; a term
/// without a usable cooling phase joins the thermal keys step 3 fits. Returns the estimates and
/// the thermal keys.
fn cooling_step(
    p: &mut Params,
    initial: &Params,
    ms: &[Measured],
    opts: &IdentifyOptions,
    notes: &mut Vec<String>,
) -> (Vec<Estimate>, Vec<ParamKey>) {
    let (fp, fc, phases) = cooling_fit(ms, opts);
    let mut thermal_keys: Vec<ParamKey> = opts.thermal_keys.clone();
    let mut step2 = Vec::new();
    for (key, fit) in [(ParamKey::Alpha2, &fp), (ParamKey::Alpha8, &fc)] {
        match fit {
            Some(f) if phases > 0 && f.beta[0] > 0.0 && f.std_err[0].is_finite() => {
                key.set(p, f.beta[0]);
                step2.push(Estimate {
                    key,
                    unit: key.unit().to_string(),
                    initial: key.get(initial),
                    value: f.beta[0],
                    std_err: f.std_err[0],
                    ci95: f.ci95[0],
                    step: "2: cooling phase (linear LS)".into(),
                    identifiable: true,
                });
            }
            _ => {
                notes.push(format!(
                    "step 2: no usable cooling phase for {key}: fitted with the other thermal terms"
                ));
                if !thermal_keys.contains(&key) {
                    thermal_keys.push(key);
                }
            }
        }
    }
    if phases > 0 {
        notes.push(format!("step 2: {phases} cooling phase(s) used"));
    }
    (step2, thermal_keys)
}

/// Step 4's keys: the kiss point's polynomial in temperature, and x_to,max when the first
/// engagement reaches it.
fn torque_keys(reaches_max: bool) -> Vec<ParamKey> {
    let mut torque_keys: Vec<ParamKey> = vec![ParamKey::XIsp0, ParamKey::XIsp1, ParamKey::XIsp2];
    if reaches_max {
        torque_keys.push(ParamKey::XToMax);
    }
    torque_keys
}

/// Steps 3–4, repeated `outer_iterations` times (at least once): the thermal fit, then the
/// torque fit, each setting its values in `p`. Returns the last of each.
fn thermal_and_torque_fits(
    p: &mut Params,
    initial: &Params,
    ms: &[Measured],
    thermal_keys: &[ParamKey],
    torque_keys: &[ParamKey],
    opts: &IdentifyOptions,
) -> (Option<lsq::Fit>, Option<lsq::Fit>) {
    let mut fit3 = None;
    let mut fit4 = None;
    for _ in 0..opts.outer_iterations.max(1) {
        let f3 = thermal_fit(p, initial, ms, thermal_keys, opts.thermal_decimate);
        if let Some(q) = with_values(p, thermal_keys, &f3.p) {
            *p = q;
        }
        let f4 = torque_fit(p, initial, ms, torque_keys);
        if let Some(q) = with_values(p, torque_keys, &f4.p) {
            *p = q;
        }
        fit3 = Some(f3);
        fit4 = Some(f4);
    }
    (fit3, fit4)
}

/// Step 5: the joint refinement of `keys5` from `p` (the temperatures and the torque weighted
/// by step 3's and 4's residual RMS, `sigmas`), its values set in `p`; with
/// `opts.split_half`, its intervals widened by split-half refits.
fn joint_refinement(
    p: &mut Params,
    initial: &Params,
    ms: &[Measured],
    keys5: &[ParamKey],
    sigmas: (f64, f64),
    opts: &IdentifyOptions,
    notes: &mut Vec<String>,
) -> lsq::Fit {
    let (st, sq) = sigmas;
    let dec = opts.thermal_decimate;
    let mut f5 = joint_fit(p, initial, ms, keys5, dec, st, sq, None, 200);
    notes.push(format!(
        "step 5: {} iterations, {}, weighted rms {:.4}, largest parameter correlation {:.3}",
        f5.iterations,
        if f5.converged {
            "converged"
        } else {
            "iteration limit"
        },
        f5.rms(),
        f5.max_abs_correlation()
    ));
    if let Some(q) = with_values(p, keys5, &f5.p) {
        *p = q;
    }
    // Split-half refits (odd and even engagement blocks) from the solution: their spread
    // measures how much the estimate depends on which engagements it saw, which the
    // residual-based interval misses when the residuals are not pure sensor noise.
    if opts.split_half {
        let a = joint_fit(p, initial, ms, keys5, dec, st, sq, Some(0), 40);
        let b = joint_fit(p, initial, ms, keys5, dec, st, sq, Some(1), 40);
        widen_by_split_half(&mut f5, &a, &b);
        notes.push(
            "step 5: intervals combine the residual-based (cluster-robust) covariance with the \
             spread of split-half refits on odd and even engagement blocks"
                .into(),
        );
    }
    f5
}

/// Widens a fit's standard errors and intervals by half the spread of two split-half refits
/// `a` and `b` (added in quadrature).
fn widen_by_split_half(f5: &mut lsq::Fit, a: &lsq::Fit, b: &lsq::Fit) {
    for j in 0..f5.p.len() {
        let half = 0.5 * (a.p[j] - b.p[j]);
        let se = (f5.std_err[j].powi(2) + half * half).sqrt();
        f5.std_err[j] = se;
        f5.ci95[j] = (f5.p[j] - lsq::Z95 * se, f5.p[j] + lsq::Z95 * se);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_stats_definition() {
        let y = [1.0, 2.0, 3.0];
        let (n, rmse, nrmse, fit) = fit_stats(&y, &y, &[true; 3]);
        assert_eq!((n, rmse, nrmse, fit), (3, 0.0, 0.0, 100.0));
        // Predicting the mean gives 0 %.
        let y = [1.0, 20.0, 40.0];
        let (_, _, nrmse, fit) = fit_stats(&y, &[20.0 + 1.0 / 3.0; 3], &[true; 3]);
        assert!(
            nrmse.is_nan() && fit.is_nan(),
            "the mean predicts nothing: not excited"
        );
        let yhat = [1.5, 19.5, 40.5];
        let (_, rmse, nrmse, fit) = fit_stats(&y, &yhat, &[true; 3]);
        assert!((rmse - 0.5).abs() < 1e-12);
        assert!((fit - 100.0 * (1.0 - nrmse)).abs() < 1e-12 && fit > 95.0);
        let (n, _, _, _) = fit_stats(&y, &y, &[true, false, true]);
        assert_eq!(n, 2);
    }
}

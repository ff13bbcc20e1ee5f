//! Recalibration and class selection (issue 17 items 2–4, 8):
//! - [`fit`]: one least-squares problem — a class's flexible term (or none) jointly with the
//!   recalibration parameters of its subsystem, on the training records, residuals standardized
//!   by each record's noise floor;
//! - the recalibration moves every parameter a bench recalibrates ([`RECAL`]: kiss-point law
//!   λ0–λ2, the dynamic and static friction levels, convection and heating terms, actuator lag),
//!   bounded to its plausible range (±[`PLAUSIBLE_REL`] of nominal) — a move beyond that is a
//!   finding of its own, not something a class is rejected for;
//! - [`select`]: forward selection of up to three classes. In each round every remaining class
//!   is fitted on top of the current model and scored on the validation records; the best is
//!   kept when (a) ΔBIC < −10 on training (sample sizes corrected for autocorrelation), (b) its
//!   validation gain Σz² is significant (paired block bootstrap, 95 % lower bound > 0), and (c)
//!   the gain is at least 10 % of the validation excess left on the channels it acts on, half
//!   their practical tolerance ([`crate::gap::method::context::tolerance`]) and 2 % of their samples.
//!   Classes whose gain is at least 80 % of the best's and whose paired bootstrap difference to
//!   it is not significant form the **ambiguity set** of that round.

use crate::gap::eval::predict::ReplayMemo;
use crate::gap::fit::lsq::{self, Fit, LmOptions, ParamSpec};
use crate::gap::fit::stats::{self, Rng};
use crate::gap::method::context::{self, File, Scores};
use crate::gap::model::candidate::{Channel, Model};
use crate::gap::model::class::ClassId;
use crate::gap::model::classes::{self, group_channels, Knots};
use crate::gap::model::keys::ParamKey;

use crate::model::effects::Subsystem;
use crate::model::params::Params;

/// The parameters plain recalibration moves, by subsystem.
pub const RECAL: &[ParamKey] = &[
    ParamKey::XIsp0,
    ParamKey::XIsp1,
    ParamKey::XIsp2,
    ParamKey::C4,
    ParamKey::MuS,
    ParamKey::Alpha2,
    ParamKey::Alpha3,
    ParamKey::Alpha8,
    ParamKey::Alpha9,
    ParamKey::TauS,
];

/// The levels among [`RECAL`] (the kiss point, the dynamic and static friction levels): moved
/// beyond their plausible range before any class is tried (level before shape).
pub const LEVELS: &[ParamKey] = &[ParamKey::XIsp0, ParamKey::C4, ParamKey::MuS];

/// Plausible recalibration: within this fraction of the nominal value.
pub const PLAUSIBLE_REL: f64 = 0.3;

/// The recalibration keys of a subsystem.
pub fn recal_keys(s: Subsystem) -> Vec<ParamKey> {
    RECAL
        .iter()
        .copied()
        .filter(|k| k.subsystem() == s)
        .collect()
}

/// Plausible range of a recalibrated parameter.
pub fn plausible(key: ParamKey, nominal: &Params) -> (f64, f64) {
    let v = key.get(nominal);
    let (a, b) = (v * (1.0 - PLAUSIBLE_REL), v * (1.0 + PLAUSIBLE_REL));
    (a.min(b), a.max(b))
}

fn recal_spec(key: ParamKey, base: &Model, nominal: &Params, wide: bool) -> ParamSpec {
    let nom = key.get(nominal);
    let v = key.get(&base.p);
    let (plo, phi) = key.range();
    let (lo, hi) = if wide {
        let (a, b) = (nom / 10.0, nom * 10.0);
        (a.min(b), a.max(b))
    } else {
        plausible(key, nominal)
    };
    let (lo, hi) = (lo.max(plo), hi.min(phi));
    let spec = ParamSpec::new(key.as_str(), v.clamp(lo, hi), lo, hi, key.scale());
    if lo > 0.0 {
        spec.log()
    } else {
        spec
    }
}

/// One fit: an optional class jointly with recalibration parameters on some channels.
#[derive(Debug, Clone)]
pub struct Job {
    /// Classes fitted together (their terms must not be in the base model).
    pub classes: Vec<ClassId>,
    /// The class's representation.
    pub form: classes::Form,
    pub recal: Vec<ParamKey>,
    pub chans: Vec<Channel>,
    /// Recalibration bounds widened to a tenth … ten times nominal.
    pub wide: bool,
    /// Reuse each record's cached disk temperature (the fit does not change the thermal model).
    pub cached_disk: bool,
    pub max_iter: usize,
}

/// A job's least-squares problem: the model of a parameter vector and its residuals.
struct Problem<'a> {
    base: &'a Model,
    job: &'a Job,
    files: &'a [File],
    knots: &'a Knots,
    /// The classes' parameter slices, then the recalibration's from `nc` on.
    slices: &'a [(ClassId, usize, usize)],
    nc: usize,
}

impl Problem<'_> {
    /// The model of the parameters `v`; `None` when its clutch parameters are not valid.
    fn build(&self, v: &[f64]) -> Option<Model> {
        let mut m = *self.base;
        for (c, a, b) in self.slices {
            c.fit()
                .apply_in(self.knots, &mut m, &v[*a..*b], self.job.form);
        }
        for (k, x) in self.job.recal.iter().zip(&v[self.nc..]) {
            k.set(&mut m.p, *x);
        }
        m.p.clutch.validate().ok()?;
        Some(m)
    }

    /// Every fit sample's scaled residual at `v` into `r`, in a fixed order (NaN predictions
    /// count as large residuals, an invalid model as larger ones).
    fn residuals(&self, v: &[f64], r: &mut [f64], memo: &mut [ReplayMemo], buf: &mut Vec<f64>) {
        let Some(model) = self.build(v) else {
            r.iter_mut().for_each(|x| *x = 1e6);
            return;
        };
        buf.clear();
        let job = self.job;
        let preds = context::fit_predictions(&model, self.files, &job.chans, job.cached_disk, memo);
        for (file, pr) in self.files.iter().zip(&preds) {
            for &c in &job.chans {
                let y = &pr.y[c.index()];
                for &k in file.fit.get(c) {
                    let e = crate::gap::eval::predict::measured(&file.m, c, k)
                        - y.get(k).copied().unwrap_or(f64::NAN);
                    buf.push(e / file.sigma[c.index()]);
                }
            }
        }
        for (ri, b) in r.iter_mut().zip(buf.iter()) {
            *ri = if b.is_finite() { *b } else { 1e3 };
        }
        for ((memo, pr), file) in memo.iter_mut().zip(preds).zip(self.files) {
            memo.recycle(pr, &file.fit);
        }
    }
}

/// A [`Problem`] as the solver sees it, with each record's replay memo: the points of a
/// Jacobian go to up to `threads` threads, each with its copy of the memo (the replays it holds
/// are shared, not copied); every point's residuals are what one thread would compute, since a
/// memo only saves work.
struct FitResiduals<'a> {
    problem: &'a Problem<'a>,
    memo: Vec<ReplayMemo>,
    buf: Vec<f64>,
    threads: usize,
}

impl lsq::Residuals for FitResiduals<'_> {
    fn eval(&mut self, p: &[f64], r: &mut [f64]) {
        self.problem.residuals(p, r, &mut self.memo, &mut self.buf);
    }

    fn eval_many(&mut self, ps: &[Vec<f64>], rs: &mut [Vec<f64>]) {
        if self.threads <= 1 || ps.len() < 2 {
            for (p, r) in ps.iter().zip(rs.iter_mut()) {
                self.eval(p, r);
            }
            return;
        }
        let (problem, memo) = (self.problem, &self.memo);
        let n = rs.first().map_or(0, Vec::len);
        let scratch = || (memo.clone(), Vec::with_capacity(n));
        let done = crate::par::map_with(self.threads, ps, scratch, |(m, buf), _, p| {
            let mut r = vec![0.0; n];
            problem.residuals(p, &mut r, m, buf);
            r
        });
        for (r, d) in rs.iter_mut().zip(done) {
            *r = d;
        }
    }
}

/// Fits `job` on the training records starting from `base`, a Jacobian's evaluations on up to
/// `threads` threads.
pub fn fit(
    base: &Model,
    nominal: &Params,
    job: &Job,
    files: &[File],
    knots: &Knots,
    threads: usize,
) -> (Model, Option<Fit>) {
    let (specs, slices, nc) = job_specs(base, nominal, job);
    let n: usize = files.iter().map(|f| f.fit.count(&job.chans)).sum();
    if specs.is_empty() || n == 0 {
        return (*base, None);
    }
    let problem = Problem {
        base,
        job,
        files,
        knots,
        slices: &slices,
        nc,
    };
    let mut f = FitResiduals {
        problem: &problem,
        memo: vec![ReplayMemo::default(); files.len()],
        buf: Vec::with_capacity(n),
        threads,
    };
    let opts = LmOptions {
        max_iter: job.max_iter,
        tol_sse: 1e-6,
        ..LmOptions::default()
    };
    let mut fit = lsq::solve(&mut f, n, &specs, opts, None);
    // A shape that zigzags (turns more than once) is fitting noise or trading against the
    // recalibration: refitted as a monotone curve in the direction of its total change, from no
    // effect, jointly with the same recalibration.
    if job.form == classes::Form::Flexible {
        if let Some(sp) = monotone_specs(&specs, &slices, &fit.p) {
            fit = lsq::solve(&mut f, n, &sp, opts, None);
        }
        // Classes whose least squares has more than one basin start again from each of their
        // other starting points (the rest of the parameters from where they started); the
        // lowest sum of squares is kept.
        for (c, a, b) in &slices {
            for start in c.fit().other_starts() {
                let mut sp = specs.clone();
                for (s, x) in sp[*a..*b].iter_mut().zip(&start) {
                    s.init = x.clamp(s.lo, s.hi);
                }
                let alt = lsq::solve(&mut f, n, &sp, opts, None);
                if alt.sse < fit.sse {
                    fit = alt;
                }
            }
        }
        if let Some(sp) = nominal_start(&specs, nc, job, nominal) {
            let alt = lsq::solve(&mut f, n, &sp, opts, None);
            if alt.sse < fit.sse {
                fit = alt;
            }
        }
    }
    let model = problem.build(&fit.p).unwrap_or(*base);
    (model, Some(fit))
}

/// The specs with the recalibration (from `nc` on) starting from nominal instead of from the
/// base model, for a job with classes whose base recalibration has a parameter on a bound;
/// `None` otherwise.
///
/// The base's recalibration was fitted without the class and absorbs what it can of the
/// effect, up to its plausible bounds: a friction fade over temperature taken up by the kiss
/// point's temperature coefficients x_isp1, x_isp2 of (9), both on their bounds. Started there,
/// the joint fit stays in that basin (a fleet's fade of −0.177 fitted as −0.077, with 1.6
/// times the sum of squares of the fit started from nominal, −0.138), so it starts again from
/// nominal and the lower sum of squares is kept. A recalibration inside its bounds has absorbed
/// nothing it had to be pushed to: no second start (it would cost half as much again).
fn nominal_start(
    specs: &[ParamSpec],
    nc: usize,
    job: &Job,
    nominal: &Params,
) -> Option<Vec<ParamSpec>> {
    let on_bound = |s: &ParamSpec| {
        let tol = 1e-6 * (s.hi - s.lo).abs();
        (s.init - s.lo).abs() <= tol || (s.hi - s.init).abs() <= tol
    };
    if job.classes.is_empty() || !specs[nc..].iter().any(on_bound) {
        return None;
    }
    let mut sp = specs.to_vec();
    let mut moved = false;
    for (s, k) in sp[nc..].iter_mut().zip(&job.recal) {
        let nom = k.get(nominal).clamp(s.lo, s.hi);
        moved |= nom != s.init;
        s.init = nom;
    }
    moved.then_some(sp)
}

/// A fit's parameter specs: the classes' parameters first (one slice each, as (class, start,
/// end)), then the recalibration's; and the number of the classes' parameters.
fn job_specs(
    base: &Model,
    nominal: &Params,
    job: &Job,
) -> (Vec<ParamSpec>, Vec<(ClassId, usize, usize)>, usize) {
    let mut specs: Vec<ParamSpec> = Vec::new();
    let mut slices = Vec::new();
    for c in &job.classes {
        let p = c.fit().params_in(base, job.form);
        slices.push((*c, specs.len(), specs.len() + p.len()));
        specs.extend(p);
    }
    let nc = specs.len();
    specs.extend(
        job.recal
            .iter()
            .map(|k| recal_spec(*k, base, nominal, job.wide)),
    );
    (specs, slices, nc)
}

/// The specs with each zigzagging shape of the fitted parameters `p` (turning more than once)
/// bounded to a monotone curve in the direction of its total change; `None` when no shape
/// zigzags.
fn monotone_specs(
    specs: &[ParamSpec],
    slices: &[(ClassId, usize, usize)],
    p: &[f64],
) -> Option<Vec<ParamSpec>> {
    let mut sp = specs.to_vec();
    let mut refit = false;
    for (c, a, _) in slices {
        let Some(r) = c.fit().increments() else {
            continue;
        };
        let r = a + r.start..a + r.end;
        if let Some(sign) = classes::zigzag_sign(&p[r.clone()]) {
            refit = true;
            for s in &mut sp[r] {
                if sign > 0.0 {
                    s.lo = s.lo.max(0.0);
                } else {
                    s.hi = s.hi.min(0.0);
                }
                s.init = s.init.clamp(s.lo, s.hi);
            }
        }
    }
    refit.then_some(sp)
}

/// The channels whose predictions a class changes (a thermal class changes the disk
/// temperature and so the torque).
pub fn affected(class: ClassId) -> Vec<Channel> {
    let mut v = class.fit().channels();
    if class.fit().group() == Subsystem::Thermal {
        v.extend(group_channels(Subsystem::TorqueCharacteristic));
    }
    v
}

/// The shared inputs of a selection.
pub struct Setup<'a> {
    pub train: &'a [File],
    pub validate: &'a [File],
    pub nominal: &'a Params,
    pub knots: &'a Knots,
    /// Channels with data in both sets.
    pub chans: &'a [Channel],
    pub nunits_v: usize,
    pub bootstrap: usize,
    pub threads: usize,
    pub bic_threshold: f64,
    pub min_gain: f64,
    /// Recalibration parameters the records do not determine: kept nominal, never refitted
    /// ([`crate::gap::method::identifiable`]).
    pub fixed: &'a [ParamKey],
}

impl Setup<'_> {
    /// The recalibration keys of a subsystem the records determine.
    pub fn recal_keys(&self, sub: Subsystem) -> Vec<ParamKey> {
        let mut keys = recal_keys(sub);
        keys.retain(|k| !self.fixed.contains(k));
        keys
    }
}

/// A class fitted on top of a model and scored.
#[derive(Debug, Clone)]
pub struct Candidate {
    pub class: ClassId,
    pub model: Model,
    pub fit: Fit,
    /// Validation scores over every channel (the unaffected ones copied from the base).
    pub val: Scores,
    pub delta_bic: f64,
    /// Validation Σz² gain over the base and its 95 % bootstrap interval.
    pub gain: f64,
    pub gain_ci95: (f64, f64),
    pub unit_gain: Vec<f64>,
    /// Validation excess Σz² − n on the affected channels before the class.
    pub excess_before: f64,
    /// Whether (a)–(c) hold, and why not.
    pub credited: bool,
    pub note: String,
}

/// Training SSE per channel of a model on the fit samples.
pub fn train_sse(model: &Model, files: &[File], chans: &[Channel], cached: bool) -> Vec<f64> {
    train_residuals(model, files, chans, cached).0
}

/// Training SSE and effective sample size per channel of a model on the fit samples.
fn train_residuals(
    model: &Model,
    files: &[File],
    chans: &[Channel],
    cached: bool,
) -> (Vec<f64>, Vec<f64>) {
    let preds = context::predictions(model, files, chans, true, cached);
    let mut r: Vec<Vec<f64>> = vec![Vec::new(); Channel::ALL.len()];
    context::for_each_residual(files, &preds, chans, true, |_, c, _, e| {
        r[c.index()].push(e)
    });
    let sse = r.iter().map(|v| v.iter().map(|e| e * e).sum()).collect();
    let n_eff = r
        .iter()
        .map(|v| {
            if v.is_empty() {
                0.0
            } else {
                lsq::effective_n(v)
            }
        })
        .collect();
    (sse, n_eff)
}

/// The fit of `classes` together on top of a model: the recalibration each class moves with it,
/// the channels it is fitted on, whether the base model's cached disk temperature serves.
/// `None` when a class has none of its channels in the records.
fn job_for(s: &Setup, classes: &[ClassId]) -> Option<Job> {
    let mut recal: Vec<ParamKey> = Vec::new();
    let mut chans: Vec<Channel> = Vec::new();
    let mut cached_disk = true;
    let present = |g: Subsystem| {
        group_channels(g)
            .into_iter()
            .filter(|c| s.chans.contains(c))
    };
    for &class in classes {
        let fit = class.fit();
        recal.extend(s.recal_keys(fit.group()));
        for &g in fit.recalibrates_also() {
            recal.extend(s.recal_keys(g));
        }
        let own: Vec<Channel> = fit
            .channels()
            .into_iter()
            .filter(|c| s.chans.contains(c))
            .collect();
        if own.is_empty() {
            return None;
        }
        chans.extend(own);
        for &g in fit.also_fitted_on() {
            chans.extend(present(g));
        }
        cached_disk &= fit.reads_cached_disk();
    }
    for c in classes.iter().map(|c| c.fit()) {
        if c.replaces_recalibration() {
            recal.retain(|k| !recal_keys(c.group()).contains(k));
        }
    }
    Some(Job {
        classes: classes.to_vec(),
        form: classes::Form::Flexible,
        recal: first_of_each(recal),
        chans: first_of_each(chans),
        wide: false,
        cached_disk,
        max_iter: 25,
    })
}

/// `v` without repeats, in the order of first appearance.
fn first_of_each<T: PartialEq + Copy>(v: Vec<T>) -> Vec<T> {
    let mut out: Vec<T> = Vec::with_capacity(v.len());
    for x in v {
        if !out.contains(&x) {
            out.push(x);
        }
    }
    out
}

/// Fits `classes` together on top of `base` ([`job_for`]); a thermal class moves the disk
/// temperature, so the torque recalibration is refitted after it. Returns the model, the fit and
/// whether the disk temperature was taken from the cache.
fn fit_classes(s: &Setup, base: &Model, classes: &[ClassId]) -> Option<(Model, Fit, bool)> {
    let job = job_for(s, classes)?;
    let (mut model, fit) = fit(base, s.nominal, &job, s.train, s.knots, s.threads);
    let fit = fit?;
    let tq: Vec<Channel> = group_channels(Subsystem::TorqueCharacteristic)
        .into_iter()
        .filter(|c| s.chans.contains(c))
        .collect();
    let thermal = classes
        .iter()
        .any(|c| c.fit().group() == Subsystem::Thermal);
    if thermal && !tq.is_empty() {
        let job = Job {
            classes: vec![],
            form: classes::Form::Flexible,
            recal: s.recal_keys(Subsystem::TorqueCharacteristic),
            chans: tq,
            wide: false,
            cached_disk: false,
            max_iter: 15,
        };
        model = fit_model(&model, s, &job);
    }
    Some((model, fit, job.cached_disk))
}

/// The channels a set of classes acts on that the records have.
fn affected_in(s: &Setup, classes: &[ClassId]) -> Vec<Channel> {
    first_of_each(
        classes
            .iter()
            .flat_map(|c| affected(*c))
            .filter(|c| s.chans.contains(c))
            .collect(),
    )
}

/// ΔBIC on training of `model` against the base's per-channel SSE over `aff`, with `k`
/// parameters, each channel's sample size corrected for the autocorrelation of the model's
/// residual (what is left once the terms are fitted; the base's residual carries the gap itself
/// and would count a large structured error as a few samples).
fn delta_bic(
    s: &Setup,
    model: &Model,
    base_train: &[f64],
    aff: &[Channel],
    cached_disk: bool,
    k: usize,
) -> f64 {
    let (t, n_eff) = train_residuals(model, s.train, aff, cached_disk);
    let (mut ll, mut neff) = (0.0, 0.0);
    for c in aff {
        let i = c.index();
        if base_train[i] > 0.0 && t[i] > 0.0 && n_eff[i] > 0.0 {
            ll += n_eff[i] * (t[i] / base_train[i]).ln();
            neff += n_eff[i];
        }
    }
    ll + k as f64 * f64::max(neff, 2.0).ln()
}

/// Fits and scores one class on top of `base`.
fn candidate(
    s: &Setup,
    base: &Model,
    base_val: &Scores,
    base_train: &[f64],
    class: ClassId,
    rng_seed: u64,
) -> Option<Candidate> {
    let (model, fit, cached_disk) = fit_classes(s, base, &[class])?;
    let aff = affected_in(s, &[class]);
    let k = class.fit().params(base).len();
    let delta_bic = delta_bic(s, &model, base_train, &aff, cached_disk, k);
    let v = Scores::of(&model, s.validate, &aff, s.nunits_v);
    let val = base_val.with(&v, &aff);
    let unit_gain = base_val.unit_gain_to(&val, s.chans);
    let gain: f64 = unit_gain.iter().sum();
    let mut rng = Rng::new(rng_seed);
    let gain_ci95 = stats::bootstrap(s.nunits_v, s.bootstrap, &mut rng, |idx| {
        idx.iter().map(|&j| unit_gain[j]).sum::<f64>()
    });
    // (c) against the gap left on the channels the class acts on, and at least half the
    // practical tolerance there (a class must not be credited for implementation differences).
    let (z_aff, n_aff) = base_val.total(&aff);
    let excess = (z_aff - n_aff).max(0.0);
    let tol: f64 = base_val.unit_tolerance(&aff).iter().sum();
    // A reading error the recalibration absorbs (a thermocouple's or torque sensor's gain and
    // offset, which the recalibrated thermal or friction parameters partly mimic) leaves little
    // on validation, yet its fitted size is a finding, not an implementation difference: the
    // tolerance rule does not apply when the fitted reading error over the channel's range is
    // above three practical tolerances.
    let absorbed = class
        .fit()
        .reading_error(&model)
        .filter(|(e, tol, _)| *e > 3.0 * tol);
    let half_tol = if absorbed.is_some() { 0.0 } else { 0.5 * tol };
    let need = (s.min_gain * excess).max(half_tol).max(0.02 * n_aff);
    let mut why = Vec::new();
    if delta_bic >= s.bic_threshold {
        why.push(format!("ΔBIC {delta_bic:.1} ≥ {}", s.bic_threshold));
    }
    if gain_ci95.0 <= 0.0 {
        why.push("validation gain not significant".to_string());
    }
    // A sensor's reading error shows in its own readings: a thermocouple class whose gain comes
    // mostly from the torque (a corrected disk-temperature estimate standing in for a
    // temperature-dependent torque effect) is not credited. Its readings must carry at least a
    // third of the gain (a point estimate: the few validation blocks of the thermocouples make
    // their own interval wide).
    if class.fit().own_readings_carry_the_gain() && gain > 0.0 {
        why.extend(torque_gain(s, class, base_val, &val, gain));
    }
    if gain < need {
        why.push(short_gain(gain, excess, s.min_gain, half_tol, tol));
    }
    Some(Candidate {
        class,
        model,
        fit,
        val,
        delta_bic,
        gain,
        gain_ci95,
        unit_gain,
        excess_before: excess,
        credited: why.is_empty(),
        note: candidate_note(&why, absorbed, gain, tol),
    })
}

/// Why a thermocouple class is not credited when its own readings carry less than a third of
/// its validation gain `gain` (the rest being the torque's); `None` otherwise.
fn torque_gain(
    s: &Setup,
    class: ClassId,
    base_val: &Scores,
    val: &Scores,
    gain: f64,
) -> Option<String> {
    let own: Vec<Channel> = class
        .fit()
        .channels()
        .into_iter()
        .filter(|c| s.chans.contains(c))
        .collect();
    let own_gain: f64 = base_val.unit_gain_to(val, &own).iter().sum();
    (own_gain < gain / 3.0).then(|| {
        format!(
            "its own readings carry {own_gain:.1} of the gain {gain:.1} (less than a third): the gain is the torque's"
        )
    })
}

/// Why a class's validation gain `gain` is too small: under half the practical tolerance `tol`
/// though it closes its share `min_gain` of the gap left `excess`, or short of that share.
fn short_gain(gain: f64, excess: f64, min_gain: f64, half_tol: f64, tol: f64) -> String {
    if gain >= min_gain * excess && gain < half_tol {
        format!(
            "closes {:.1} % of the gap left, but {gain:.1} is less than half the practical \
             tolerance {tol:.1} (an implementation difference, not an effect)",
            100.0 * gain / excess.max(1e-9)
        )
    } else {
        format!(
            "closes {:.1} % < {:.0} % of the validation gap left",
            100.0 * gain / excess.max(1e-9),
            100.0 * min_gain
        )
    }
}

/// A candidate's note: "credited" (with the reading error the recalibration largely absorbs,
/// when its gain is under half the tolerance `tol`), else the reasons `why` it is not.
fn candidate_note(
    why: &[String],
    absorbed: Option<(f64, f64, &'static str)>,
    gain: f64,
    tol: f64,
) -> String {
    if why.is_empty() {
        match absorbed {
            Some((e, _, unit)) if gain < 0.5 * tol => format!(
                "credited: a reading error of {e:.2} {unit} over the channel's range, largely \
                 absorbed by the recalibration (ambiguous with it on these records)"
            ),
            _ => "credited".into(),
        }
    } else {
        why.join("; ")
    }
}

/// Fits a job and returns only the model.
pub fn fit_model(base: &Model, s: &Setup, job: &Job) -> Model {
    fit(base, s.nominal, job, s.train, s.knots, s.threads).0
}

/// One round of the selection.
#[derive(Debug, Clone)]
pub struct Round {
    /// Every candidate of the round, best validation score first.
    pub candidates: Vec<Candidate>,
    /// Index of the kept candidate, if any.
    pub kept: Option<usize>,
    /// Classes as good as the kept one (its ambiguity set without it).
    pub ambiguous: Vec<ClassId>,
    /// The kept class was dropped by the backward check (not significant once the classes
    /// selected after it were in).
    pub dropped: bool,
    /// The class this round first kept, replaced by the swap check (the candidates are then
    /// those of the swap round).
    pub replaced: Option<ClassId>,
}

/// Fits every class of `classes` on top of `base` on the available cores.
fn round(
    s: &Setup,
    base: &Model,
    base_val: &Scores,
    classes: &[ClassId],
    seed: u64,
) -> Vec<Candidate> {
    let aff_all: Vec<Channel> = s.chans.to_vec();
    let base_train = train_sse(base, s.train, &aff_all, false);
    let mut out = on_cores(s.threads, classes, |i, c| {
        candidate(s, base, base_val, &base_train, *c, seed ^ (i as u64 + 1))
    });
    // Best gain first; equal gains in the order of `classes`, whichever thread fitted them.
    out.sort_by(|a, b| b.1.gain.total_cmp(&a.1.gain).then(a.0.cmp(&b.0)));
    out.into_iter().map(|(_, k)| k).collect()
}

/// Forward selection of up to `max_classes` classes from `classes`, starting at `base`, then
/// the swap and backward checks.
pub fn select(
    s: &Setup,
    base: &Model,
    classes: &[ClassId],
    max_classes: usize,
    seed: u64,
) -> (Model, Scores, Vec<Round>) {
    let mut sel = Selection {
        model: *base,
        val: Scores::of(base, s.validate, s.chans, s.nunits_v),
        rounds: Vec::new(),
        chosen: Vec::new(),
    };
    for r in 0..max_classes {
        let left: Vec<ClassId> = classes
            .iter()
            .copied()
            .filter(|c| !sel.chosen.iter().any(|k| classes::conflicts(*k, *c)))
            .collect();
        if left.is_empty() {
            break;
        }
        let cands = round(
            s,
            &sel.model,
            &sel.val,
            &left,
            seed.wrapping_add(r as u64 * 7919),
        );
        for c in &cands {
            tracing::debug!(
                "round {r}: {} gain {:.1} (95 % CI {:.1}…{:.1}), ΔBIC {:.1}, excess {:.1}: {}",
                c.class,
                c.gain,
                c.gain_ci95.0,
                c.gain_ci95.1,
                c.delta_bic,
                c.excess_before,
                c.note
            );
        }
        let kept = cands.iter().position(|c| c.credited);
        let mut ambiguous = Vec::new();
        if let Some(b) = kept {
            let best = &cands[b];
            ambiguous = as_good_as(s, &sel.val, &cands, b, seed);
            sel.model = best.model;
            sel.val = best.val.clone();
            sel.chosen.push(best.class);
        }
        let stop = kept.is_none();
        tracing::debug!(
            "round {r}: {} classes fitted, kept {:?}",
            cands.len(),
            kept.map(|b| cands[b].class)
        );
        sel.rounds.push(Round {
            candidates: cands,
            kept,
            ambiguous,
            dropped: false,
            replaced: None,
        });
        if stop {
            break;
        }
    }
    swap(s, base, classes, &mut sel, seed);
    tracing::debug!("swap check done");
    backward(s, base, &mut sel, seed);
    tracing::debug!("backward check done");
    (sel.model, sel.val, sel.rounds)
}

/// The selection so far: the model with the kept classes and its validation scores, every
/// round, and the kept classes in order (`chosen[i]` is the class round `i` kept).
struct Selection {
    model: Model,
    val: Scores,
    rounds: Vec<Round>,
    chosen: Vec<ClassId>,
}

/// 95 % block-bootstrap interval of the validation gain of `a` minus that of `b`, paired over
/// the validation units.
fn paired_difference(s: &Setup, a: &Candidate, b: &Candidate, seed: u64) -> (f64, f64) {
    let d: Vec<f64> = a
        .unit_gain
        .iter()
        .zip(&b.unit_gain)
        .map(|(x, y)| x - y)
        .collect();
    let mut rng = Rng::new(seed);
    stats::bootstrap(s.nunits_v, s.bootstrap, &mut rng, |idx| {
        idx.iter().map(|&u| d[u]).sum::<f64>()
    })
}

/// Credited candidates as good as candidate `b` of a round (fitted on `base`'s validation
/// scores): at least 80 % of its gain, and either a paired (block bootstrap) difference that is
/// not significant or a change of the validation predictions that is nearly collinear with the
/// best's ([`collinear`]): the records cannot tell the two apart, however close their fits.
fn as_good_as(s: &Setup, base: &Scores, cands: &[Candidate], b: usize, seed: u64) -> Vec<ClassId> {
    let best = &cands[b];
    let mut out = Vec::new();
    for (j, c) in cands.iter().enumerate() {
        if j == b || !c.credited || c.gain < 0.8 * best.gain {
            continue;
        }
        let ci = paired_difference(s, best, c, seed ^ 0xA5A5 ^ j as u64);
        let cos = collinear(s, base, best, c);
        tracing::debug!(
            "{} beside {}: gain {:.1} against {:.1}, paired difference 95 % CI {:.1}…{:.1}, \
             cosine of their changes {cos:.4}",
            c.class,
            best.class,
            c.gain,
            best.gain,
            ci.0,
            ci.1
        );
        if ci.0 <= 0.0 || cos >= MIN_COLLINEAR {
            out.push(c.class);
        }
    }
    out
}

/// Two classes whose changes of the standardized validation predictions make a smaller angle
/// than this (cosine; 8.1°) are an ambiguity set: their predictions differ by less than a
/// seventh of what either changes.
pub const MIN_COLLINEAR: f64 = 0.99;

/// The cosine of the angle between what candidates `a` and `b` change in the validation
/// predictions against `base`, each residual standardized by its record's floor, over every
/// checked channel.
fn collinear(s: &Setup, base: &Scores, a: &Candidate, b: &Candidate) -> f64 {
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (i, f) in s.validate.iter().enumerate() {
        let (p0, pa, pb) = (&base.preds[i], &a.val.preds[i], &b.val.preds[i]);
        for &c in s.chans {
            let k = c.index();
            let (y0, ya, yb) = (&p0.y[k], &pa.y[k], &pb.y[k]);
            if y0.is_empty() || ya.is_empty() || yb.is_empty() {
                continue;
            }
            let sigma = f.sigma[k].max(1e-12);
            for &t in f.all.get(c) {
                let (da, db) = ((ya[t] - y0[t]) / sigma, (yb[t] - y0[t]) / sigma);
                if da.is_finite() && db.is_finite() {
                    ab += da * db;
                    aa += da * da;
                    bb += db * db;
                }
            }
        }
    }
    if aa <= 0.0 || bb <= 0.0 {
        return 0.0;
    }
    ab / (aa * bb).sqrt()
}

/// Contenders of the swap check for each kept class: at most this many of its round's runners-up.
const SWAP_CONTENDERS: usize = 5;

/// Swap check (with two or more classes selected): each selected class is taken out in turn
/// and its round's strongest runners-up that can stand beside the others (kept-quality, or a
/// gain of at least a quarter of the kept class's; at most [`SWAP_CONTENDERS`]) are fitted in
/// its place beside it; the class is replaced when another one gains significantly more there
/// (paired block bootstrap). A class that won its round only through an effect a later class
/// explains — a torque class read against a disk temperature a thermocouple lag distorted — is
/// then replaced by the class that explains what is left once the later class is in. (Every
/// class in its place cost a full round per kept class: 75 of the 244 s of a 30-minute log's
/// diagnosis, `scripts/gap-acceptance` part 3.)
fn swap(s: &Setup, base: &Model, classes: &[ClassId], sel: &mut Selection, seed: u64) {
    if sel.chosen.len() < 2 {
        return;
    }
    for i in 0..sel.chosen.len() {
        let c = sel.chosen[i];
        let mut without = sel.model;
        c.fit().remove(&mut without, base);
        let left: Vec<ClassId> = contenders(&sel.rounds[i], c)
            .into_iter()
            .filter(|k| classes.contains(k))
            .filter(|k| {
                !sel.chosen
                    .iter()
                    .any(|o| *o != c && classes::conflicts(*o, *k))
            })
            .collect();
        if left.len() < 2 {
            continue;
        }
        let without_val = Scores::of(&without, s.validate, s.chans, s.nunits_v);
        let round_seed = seed.wrapping_add(0x5A9 + i as u64 * 7919);
        let cands = round(s, &without, &without_val, &left, round_seed);
        let (Some(b), Some(own)) = (
            cands.iter().position(|k| k.credited),
            cands.iter().find(|k| k.class == c),
        ) else {
            continue;
        };
        let best = &cands[b];
        if best.class == c {
            continue;
        }
        let ci = paired_difference(s, best, own, seed ^ 0x5A95 ^ i as u64);
        tracing::debug!(
            "swap {c} → {}: gain {:.1} against {:.1}, difference 95 % CI {:.1}…{:.1}",
            best.class,
            best.gain,
            own.gain,
            ci.0,
            ci.1
        );
        if ci.0 <= 0.0 {
            continue;
        }
        sel.model = best.model;
        sel.val = best.val.clone();
        sel.chosen[i] = best.class;
        let ambiguous = as_good_as(s, &without_val, &cands, b, round_seed);
        let r = &mut sel.rounds[i];
        r.candidates = cands;
        r.kept = Some(b);
        r.ambiguous = ambiguous;
        r.replaced = Some(c);
    }
}

/// The kept class `c` of round `r` and the runners-up the swap check fits in its place.
fn contenders(r: &Round, c: ClassId) -> Vec<ClassId> {
    let own_gain = r
        .candidates
        .iter()
        .find(|k| k.class == c)
        .map_or(0.0, |k| k.gain);
    let runners = r
        .candidates
        .iter()
        .filter(|k| k.class != c && (k.credited || k.gain >= 0.25 * own_gain))
        .take(SWAP_CONTENDERS)
        .map(|k| k.class);
    std::iter::once(c).chain(runners).collect()
}

/// The selected classes but `c` refitted jointly with the recalibration of every selected
/// class's subsystem, from `base` (the backward check's model without `c`).
fn refit_without(
    s: &Setup,
    base: &Model,
    current: &Model,
    chosen: &[ClassId],
    c: ClassId,
) -> Model {
    let others: Vec<ClassId> = chosen.iter().copied().filter(|k| *k != c).collect();
    let mut b = *current;
    for k in chosen {
        k.fit().remove(&mut b, base);
    }
    let mut groups: Vec<Subsystem> = chosen.iter().map(|k| k.fit().group()).collect();
    groups.sort();
    groups.dedup();
    let recal: Vec<ParamKey> = groups.iter().flat_map(|g| s.recal_keys(*g)).collect();
    let mut chans: Vec<Channel> = chosen
        .iter()
        .flat_map(|k| k.fit().channels())
        .filter(|ch| s.chans.contains(ch))
        .collect();
    chans.sort();
    chans.dedup();
    let job = Job {
        classes: others,
        form: classes::Form::Flexible,
        recal,
        chans,
        wide: false,
        cached_disk: false,
        max_iter: 25,
    };
    fit_model(&b, s, &job)
}

/// [`refit_without`] for every selected class at once, on the available cores.
fn refits_without(s: &Setup, base: &Model, current: &Model, chosen: &[ClassId]) -> Vec<Model> {
    let mut out = on_cores(s.threads, chosen, |_, c| {
        Some(refit_without(s, base, current, chosen, *c))
    });
    out.sort_by_key(|(i, _)| *i);
    out.into_iter().map(|(_, m)| m).collect()
}

/// `f(i, class)` for every class on up to `threads` threads ([`crate::par::map_costliest_first`]:
/// a shared queue, the costliest fits taken first), with its index; `None` results dropped.
fn on_cores<R: Send>(
    threads: usize,
    items: &[ClassId],
    f: impl Fn(usize, &ClassId) -> Option<R> + Sync,
) -> Vec<(usize, R)> {
    crate::par::map_costliest_first(threads, items, |c| c.fit().fit_cost(), f)
        .into_iter()
        .enumerate()
        .filter_map(|(i, r)| r.map(|r| (i, r)))
        .collect()
}

/// What a selected class is worth beside the others: the validation gain lost when it is taken
/// out and the others refitted (`without`), against the model with it (`with`).
#[derive(Debug, Clone)]
struct Loss {
    /// Summed over the validation units, with its 95 % block-bootstrap interval.
    gain: f64,
    ci95: (f64, f64),
    /// What the forward step asks of a class here: 10 % of the excess left without it, half the
    /// practical tolerance, 2 % of the samples.
    need: f64,
}

impl Loss {
    /// The loss is measured on the class's own channels: the others' refit moves their channels
    /// too, and on a channel a large effect dominates (a position sensor's error 300 times the
    /// thermal one) that refit's scatter would swamp the class's loss.
    fn of(s: &Setup, without: &Scores, with: &Scores, c: ClassId, seed: u64) -> Loss {
        let own: Vec<Channel> = affected(c)
            .into_iter()
            .filter(|ch| s.chans.contains(ch))
            .collect();
        let unit = without.unit_gain_to(with, &own);
        let gain: f64 = unit.iter().sum();
        let mut rng = Rng::new(seed);
        let ci95 = stats::bootstrap(s.nunits_v, s.bootstrap, &mut rng, |idx| {
            idx.iter().map(|&j| unit[j]).sum::<f64>()
        });
        let (z, n) = without.total(&own);
        let tol: f64 = without.unit_tolerance(&own).iter().sum();
        let need = (s.min_gain * (z - n).max(0.0)).max(0.5 * tol).max(0.02 * n);
        Loss { gain, ci95, need }
    }

    /// The class is still needed: its loss is significant and at least what the forward step
    /// asks.
    fn needed(&self) -> bool {
        self.ci95.0 > 0.0 && self.gain >= self.need
    }
}

/// Backward check: each selected class is removed in turn and the others refitted jointly with
/// the recalibration; the class is dropped when the (c) and (b) criteria of the forward step no
/// longer hold for it (a class that only explained what a later class explains better). The
/// refits of the selection as it stands are computed together on the available cores; once a
/// class is dropped, the later ones are refitted on what is left.
fn backward(s: &Setup, base: &Model, sel: &mut Selection, seed: u64) {
    let Selection {
        model: current,
        val: cur_val,
        rounds,
        chosen,
    } = sel;
    if chosen.len() < 2 {
        return;
    }
    let first_pass = refits_without(s, base, current, chosen);
    let mut dropped_any = false;
    for (i, c) in chosen.clone().into_iter().enumerate() {
        if chosen.len() < 2 {
            return;
        }
        let minus = if dropped_any {
            refit_without(s, base, current, chosen, c)
        } else {
            first_pass[i]
        };
        let mut aff: Vec<Channel> = chosen
            .iter()
            .flat_map(|k| affected(*k))
            .filter(|ch| s.chans.contains(ch))
            .collect();
        aff.sort();
        aff.dedup();
        let v_minus = cur_val.with(&Scores::of(&minus, s.validate, &aff, s.nunits_v), &aff);
        let loss = Loss::of(s, &v_minus, cur_val, c, seed ^ 0xBAC4 ^ c as u64);
        tracing::debug!(
            "backward {c}: gain {:.1} (95 % CI {:.1}…{:.1}), need {:.1}",
            loss.gain,
            loss.ci95.0,
            loss.ci95.1,
            loss.need
        );
        if !loss.needed() {
            dropped_any = true;
            *current = minus;
            *cur_val = v_minus;
            chosen.retain(|k| *k != c);
            for r in rounds.iter_mut() {
                if r.kept.map(|k| r.candidates[k].class) == Some(c) {
                    r.dropped = true;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn torque_job(classes: Vec<ClassId>) -> Job {
        Job {
            classes,
            form: classes::Form::Flexible,
            recal: recal_keys(Subsystem::TorqueCharacteristic),
            chans: vec![],
            wide: false,
            cached_disk: true,
            max_iter: 1,
        }
    }

    /// The joint fit starts again from the nominal recalibration only where the base's
    /// recalibration sits on a plausible bound, and only the recalibration's starts move.
    #[test]
    fn a_second_start_from_nominal_only_where_the_base_sits_on_a_bound() {
        let nominal = Params::default();
        let job = torque_job(vec![ClassId::FrictionTemperature]);
        let mut base = Model::nominal(nominal);
        ParamKey::C4.set(&mut base.p, 0.36);
        let (specs, _, nc) = job_specs(&base, &nominal, &job);
        assert!(nc > 0 && specs.len() > nc);
        assert_eq!(nominal_start(&specs, nc, &job, &nominal), None);
        // λ2 pushed to its bound, as a friction fade pushes it.
        let (lo, hi) = plausible(ParamKey::XIsp2, &nominal);
        let bound = if lo.abs() < hi.abs() { lo } else { hi };
        ParamKey::XIsp2.set(&mut base.p, bound);
        let (specs, _, nc) = job_specs(&base, &nominal, &job);
        let sp = nominal_start(&specs, nc, &job, &nominal).expect("a second start");
        assert_eq!(sp[..nc], specs[..nc]);
        for (s, k) in sp[nc..].iter().zip(&job.recal) {
            assert_eq!(s.init, k.get(&nominal), "{k}");
            let old = specs.iter().find(|o| o.name == s.name).unwrap();
            assert_eq!((s.lo, s.hi), (old.lo, old.hi), "{k}: bounds unchanged");
        }
        // A recalibration alone (no class) has no second start.
        let alone = torque_job(vec![]);
        let (specs, _, nc) = job_specs(&base, &nominal, &alone);
        assert_eq!(nominal_start(&specs, nc, &alone, &nominal), None);
    }
}

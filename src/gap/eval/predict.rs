//! A candidate [`Model`] evaluated on measured data channel by channel ([`Channel`]) exactly as in
//! [`crate::gap::eval::replay`]: torque in equation-error form at the measured x_to and slip with the disk
//! temperature estimated from measured temperatures, plate/central-disk temperatures by thermal
//! replay from the measured friction power, bearing positions by actuator replay from the
//! requests, the engine torque report from the flywheel balance (18a).
//!
//! This module is the thin adapter between the library and the diagnosis: [`SetHooks`] exposes an
//! effect set as powertrain hooks (β and extra heat for the replays), [`bearing_sequence`] runs
//! the backlash play over the measured actuator positions, [`delayed_requests`] applies a dead
//! time to logged requests.

#![allow(clippy::needless_range_loop)]

use crate::gap::eval::set_hooks::SetHooks;
use crate::gap::model::candidate::{Channel, Model, ENGINE_WINDOW};
use crate::gap::record::series;
use std::sync::Arc;

use crate::gap::eval::disk::{self, DiskRun};
use crate::gap::eval::replay;
use crate::gap::model::shape::Shape;
use crate::gap::model::terms::{self, Extra, Surface, Terms, X_REF_MM};
use crate::gap::record::measured::{Measured, Shared};
use crate::gap::record::slip_shapes::SlipShapes;
use crate::model::clutch;
use crate::model::effects::{self, EffectId, EffectSet, TorqueContext};
use crate::model::params::{ActuatorParams, ClutchParams};
use crate::model::powertrain::{ClutchContext, Hooks};
use crate::model::thermal::{Thermal5State, ThermalInputs};

impl SetHooks {
    /// The hooks of a model: its library effects and its thermal class terms.
    pub fn of(m: &Model) -> Self {
        let t = &m.terms;
        let any = t.support.is_some() || t.convection.is_some() || t.partition.is_some();
        SetHooks(
            m.set,
            any.then_some(terms::ThermalTerms {
                a: m.p.thermal5,
                support: t.support,
                convection: t.convection,
                partition: t.partition,
            }),
        )
    }
}

fn torque_context(c: &ClutchContext) -> TorqueContext {
    TorqueContext {
        x_to_mm: c.x_to_mm,
        slip_radps: c.slip_radps,
        theta_c: c.theta_c,
        theta_pp: c.theta_pp,
        theta_cd: c.theta_cd,
        e_fric_j: c.e_fric_j,
        theta_surface_c: c.theta_c,
        slip_accel_radps2: 0.0,
        slip_shape: None,
    }
}

impl Hooks for SetHooks {
    #[inline]
    fn clutch_torque(&self, p: &ClutchParams, c: &ClutchContext) -> f64 {
        effects::torque(p, &self.0, &torque_context(c))
    }
    #[inline]
    fn clutch_capacity(&self, p: &ClutchParams, c: &ClutchContext) -> f64 {
        effects::capacity(p, &self.0, &torque_context(c))
    }
    #[inline]
    fn clutch_beta(&self, p: &ClutchParams, c: &ClutchContext) -> f64 {
        effects::beta(p, &self.0, &torque_context(c))
    }
    #[inline]
    fn engine_command(&self, nominal_nm: f64, _w_f_radps: f64) -> f64 {
        effects::engine_real_torque(&self.0, nominal_nm)
    }
    #[inline]
    fn extra_heat(&self, s: &Thermal5State, u: &ThermalInputs) -> Thermal5State {
        let e = effects::thermal5_extra(&self.0, s, u);
        match &self.1 {
            Some(t) => e.axpy(1.0, &t.rates(s, u)),
            None => e,
        }
    }
}

/// Samples of a file used for each channel.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Samples {
    /// Per channel (indexed like [`Channel::ALL`]).
    pub idx: Vec<Vec<usize>>,
    /// Step of the temperature samples (every `temp_stride`-th sample): the thermal replay
    /// steps by it.
    pub temp_stride: usize,
}

impl Samples {
    /// The samples of every channel the file can check: slipping clutch samples near or past the
    /// kiss point (torque), every `temp_stride`-th valid sample (temperatures), every valid sample
    /// when the requests are logged (positions), samples where the engine transmits through a
    /// clutch (engine). `torque_stride` thins the torque samples (for fitting).
    pub fn new(m: &Measured, torque_stride: usize, temp_stride: usize) -> Samples {
        let mut idx = vec![Vec::new(); Channel::ALL.len()];
        for i in 0..2 {
            idx[Channel::Torque(i).index()] = m.torque_idx[i]
                .iter()
                .copied()
                .filter(|&k| m.slip[i][k].abs() >= 0.5)
                .step_by(torque_stride.max(1))
                .collect();
        }
        let temps: Vec<usize> = (0..m.n)
            .step_by(temp_stride.max(1))
            .filter(|&k| m.valid[k])
            .collect();
        for j in 0..3 {
            idx[Channel::Temp(j).index()] = temps.clone();
        }
        for i in 0..2 {
            if m.x_req[i].is_some() {
                idx[Channel::Pos(i).index()] = (0..m.n).filter(|&k| m.valid[k]).collect();
            }
        }
        if let Some(te) = m.t_e.as_ref().filter(|_| !m.rig) {
            // The flywheel balance is informative where the engine drives a slipping or locked
            // clutch with a real torque; on the rig the dyno replaces the engine (the report then
            // is the dyno torque and every model agrees). One sample per window start.
            let w = ENGINE_WINDOW;
            idx[Channel::Engine.index()] = (0..m.n.saturating_sub(w + 1))
                .step_by(w)
                .filter(|&k| {
                    (k..=k + w).all(|j| m.valid[j] && te[j].abs() > 10.0 && m.w_f[j] > 50.0)
                })
                .collect();
        }
        Samples {
            idx,
            temp_stride: temp_stride.max(1),
        }
    }

    pub fn get(&self, c: Channel) -> &[usize] {
        &self.idx[c.index()]
    }

    /// Total number of samples of a channel set.
    pub fn count(&self, chans: &[Channel]) -> usize {
        chans.iter().map(|c| self.get(*c).len()).sum()
    }
}

/// Bearing positions behind the backlash of `set` for the measured actuator positions (the
/// measured positions themselves without backlash).
pub fn bearing_sequence(set: &EffectSet, m: &Measured) -> Option<[Vec<f64>; 2]> {
    let b = set.get(EffectId::ActuatorBacklash)?[0];
    if b <= 0.0 {
        return None;
    }
    Some([0, 1].map(|i| {
        let mut out = Vec::with_capacity(m.n);
        let mut bear = m.x[i][0];
        for k in 0..m.n {
            bear = effects::backlash(b, bear, m.x[i][k]);
            out.push(bear);
        }
        out
    }))
}

/// Logged requests delayed by the set's dead time (linear interpolation between samples).
pub fn delayed_requests(set: &EffectSet, xr: &[f64], dt: f64) -> Vec<f64> {
    let d = effects::dead_time_s(set);
    if d <= 0.0 {
        return xr.to_vec();
    }
    (0..xr.len())
        .map(|k| effects::delayed_sample(xr, k, dt, d))
        .collect()
}

/// Predictions of one model on one file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Predictions {
    /// Per channel, the prediction at every sample of the file (NaN where not evaluated).
    pub y: Vec<Vec<f64>>,
    /// The disk temperatures used for the torque (°C).
    pub disk: Option<[Vec<f64>; 2]>,
}

/// Measured value of a channel at sample k.
#[inline]
pub fn measured(m: &Measured, c: Channel, k: usize) -> f64 {
    match c {
        Channel::Torque(i) => m.torque[i][k],
        Channel::Temp(0) => m.pp[0][k],
        Channel::Temp(1) => m.pp[1][k],
        Channel::Temp(_) => m.cd[k],
        Channel::Pos(i) => m.x[i][k],
        Channel::Engine => m.t_e.as_ref().map_or(f64::NAN, |v| window_mean(v, k)),
    }
}

/// Trapezoidal mean of a signal over the engine window starting at k.
#[inline]
fn window_mean(v: &[f64], k: usize) -> f64 {
    let w = ENGINE_WINDOW;
    if k + w >= v.len() {
        return f64::NAN;
    }
    let s: f64 = (k..k + w).map(|j| 0.5 * (v[j] + v[j + 1])).sum();
    s / w as f64
}

/// Hidden facing-surface temperatures along the record, exact per sample with the measured
/// friction power and the disk temperature estimate: the flexible term when the model has one
/// ([`Surface`](crate::gap::model::terms::Surface)), else the library's `surface_temperature_friction`
/// member (θ̇_s = h·P − (θ_s − θ_c)/τ_s).
fn surface_temperatures(surface: &Surface, m: &Measured, disk: &[Vec<f64>; 2]) -> [Vec<f64>; 2] {
    let a = (-m.dt / surface.tau_s.max(1e-3)).exp();
    let mut out = [Vec::with_capacity(m.n), Vec::with_capacity(m.n)];
    if m.n == 0 {
        return out;
    }
    let sites = m.power_sites(&surface.rise);
    // Both clutches in one loop: two independent chains of steps side by side.
    let mut th = [disk[0][0], disk[1][0]];
    for k in 0..m.n {
        for i in 0..2 {
            out[i].push(th[i]);
            th[i] = surface.step_at(th[i], disk[i][k], sites.at(i, k), a);
        }
    }
    out
}

/// The surface-temperature model of `model`: the flexible term when it has one, else the
/// library's `surface_temperature_friction` member as a term; `None` without either.
fn surface_of(model: &Model) -> Option<Surface> {
    if let Some(s) = model.terms.surface {
        return Some(s);
    }
    let v = model.set.get(EffectId::SurfaceTemperatureFriction)?;
    let tau = v[1].max(1e-3);
    // The member's rise h·P·τ as a straight curve.
    let z = std::array::from_fn(|j| j as f64 * 1e4);
    Some(Surface {
        rise: Shape {
            z,
            v: z.map(|p| v[0] * p * tau),
        },
        tau_s: tau,
    })
}

/// Model torque of clutch `i` at sample `k` (before the torque sensor).
#[allow(clippy::too_many_arguments)]
#[inline]
fn torque_at(
    model: &Model,
    m: &Measured,
    dk: &[Vec<f64>; 2],
    bearing: Option<&[Vec<f64>; 2]>,
    surface: Option<&[Vec<f64>; 2]>,
    slide: Option<&[Vec<f64>; 2]>,
    shapes: &SlipShapes,
    i: usize,
    k: usize,
) -> f64 {
    let mut ctx = m.context(i, k, dk[i][k]);
    if let Some(b) = bearing {
        ctx.x_to_mm = b[i][k];
    }
    ctx.x_to_mm = model.terms.bearing(ctx.x_to_mm);
    let mut tc = torque_context(&ctx);
    tc.slip_shape = Some(shapes.at(i, k));
    if let Some(s) = surface {
        tc.theta_surface_c = s[i][k];
    }
    let extra = Extra {
        slide_acc: slide.map_or(0.0, |v| v[i][k]),
    };
    model.terms.torque(&model.p.clutch, &model.set, &tc, &extra)
}

/// Evaluates `model` on the channels `chans` of file `m` at the samples `s` (the others NaN).
pub fn predict(model: &Model, m: &Measured, s: &Samples, chans: &[Channel]) -> Predictions {
    let corrected = corrected_inputs(&model.terms, m);
    let mm = corrected.as_ref().unwrap_or(m);
    let disk =
        want_torque(s, chans).then(|| replay::disk_estimate(&model.p, &SetHooks::of(model), mm));
    let mut pr = predict_inner(model, mm, s, chans, disk.as_ref(), Reuse::default());
    pr.disk = disk;
    pr
}

/// The measured inputs of the replays as the sensor terms say they really were: thermocouple
/// readings corrected for their reading error, then un-lagged (θ + τ·dθ/dt, derivative over
/// ±1 s), the speeds (slip, flywheel) as the speed sensors' gain and skew say they were, the
/// friction power and energy from the corrected torque and slip. `None` without sensor
/// terms. The free replays start from the corrected readings before the un-lag
/// ([`Measured::start`]: the un-lag's noise would last in the slow states).
fn corrected_inputs(t: &Terms, m: &Measured) -> Option<Measured> {
    if !corrects_inputs(t) {
        return None;
    }
    let mut c = m.clone();
    if let Some(g) = &t.temp_sensor {
        let inv = g.inverse();
        let read = |v: &Shared| -> Shared { v.iter().map(|x| inv.eval(*x)).collect() };
        c.pp = [read(&m.pp[0]), read(&m.pp[1])];
        c.cd = read(&m.cd);
        c.start = c.thermal_at(0);
    }
    if t.temp_lag_s > 0.0 {
        let half = ((1.0 / m.dt).round() as usize).max(1);
        let unlag = |v: &Shared| -> Shared {
            let d = series::derivative(v, m.dt, half);
            v.iter()
                .zip(&d)
                .map(|(x, dx)| x + t.temp_lag_s * dx)
                .collect()
        };
        c.pp = [unlag(&c.pp[0]), unlag(&c.pp[1])];
        c.cd = unlag(&c.cd);
    }
    if let Some(sp) = &t.speed_sensor {
        let speeds = |v: &Shared| -> Shared { sp.true_speeds(v, m.dt) };
        c = c.with_speeds([speeds(&m.slip[0]), speeds(&m.slip[1])], speeds(&m.w_f));
    }
    if t.torque_sensor.is_some() || t.speed_sensor.is_some() {
        let mut e_cum = m.e_cum.clone();
        let power = [0, 1].map(|i| {
            let measured = m.torque[i].iter().zip(&c.slip[i][..]);
            let power: Shared = match &t.torque_sensor {
                Some(g) => measured.map(|(tq, w)| g.invert(*tq, 0.0) * w).collect(),
                None => measured.map(|(tq, w)| tq * w).collect(),
            };
            let e0 = m.e_cum[i].first().copied().unwrap_or(0.0);
            e_cum[i] = series::cumulative_energy(&power, e0, m.dt);
            power
        });
        c = c.with_power(power, e_cum);
    }
    Some(c)
}

/// The inputs and disk temperature estimate a [`predict`] replayed for the models a fit evaluated
/// last on one record. A fit's Jacobian moves one parameter at a time; most move only the torque
/// characteristic's terms, under which the record's corrected inputs and disk replay stay what
/// they were, and a thermal parameter moves the replay but not the corrected inputs:
/// [`predict_reusing`] takes them from here instead of computing them again. Two entries each:
/// the point of the Jacobian stays while a column that does move them is evaluated.
#[derive(Debug, Clone, Default)]
pub struct ReplayMemo {
    inputs: Vec<(Terms, Option<Measured>)>,
    disks: Vec<(ReplayKey, DiskRun)>,
    actuator: ActuatorMemo,
    /// Surface temperatures over the record's cached disk estimate ([`predict_with_disk_ref`]),
    /// keyed by the surface model: a fit's columns of the torque recalibration leave it as it
    /// was.
    surface: SurfaceMemo,
    spare: Spare,
}

/// Surface temperatures of both clutches kept by surface model and the disk estimate they were
/// computed on (a copy, compared bit for bit: an equal estimate wherever it is stored finds the
/// entry, another one never does), the last used first, two at most.
type SurfaceMemo = Vec<(Surface, [Vec<f64>; 2], Arc<[Vec<f64>; 2]>)>;

/// The surface temperatures of `sf` over the disk estimate `dk` from `kept`, else made by `make`
/// (and kept).
fn recall_surface(
    kept: &mut SurfaceMemo,
    sf: Surface,
    dk: &[Vec<f64>; 2],
    make: impl FnOnce() -> Arc<[Vec<f64>; 2]>,
) -> Arc<[Vec<f64>; 2]> {
    let same = |d: &[Vec<f64>; 2]| (0..2).all(|i| same_bits(&d[i], &dk[i]));
    match kept.iter().position(|(s, d, _)| *s == sf && same(d)) {
        Some(i) => kept[..=i].rotate_right(1),
        None => {
            let made = make();
            kept.insert(0, (sf, dk.clone(), made));
            kept.truncate(2);
        }
    }
    kept[0].2.clone()
}

/// Whether two series hold the same numbers, bit for bit (NaN included).
fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// Per channel, a prediction vector whose residuals a fit has taken ([`ReplayMemo::recycle`]):
/// NaN but at the channel's samples, which the next prediction on the same samples writes again
/// (so it is NaN wherever that prediction does not evaluate, as a fresh one), without filling a
/// record-long vector with NaN per channel and evaluation. Not cloned: a thread's copy of the
/// memo starts without.
#[derive(Debug, Default)]
struct Spare(Vec<Option<SpareVec>>);

/// A spare vector and the samples it holds values at (their indices, compared by value).
#[derive(Debug)]
struct SpareVec {
    at: Vec<usize>,
    v: Vec<f64>,
}

impl Clone for Spare {
    fn clone(&self) -> Self {
        Spare::default()
    }
}

impl Spare {
    /// A vector of `n` for channel `c` at the samples `at`: NaN but where the previous one of
    /// the same samples had values (which the caller overwrites).
    fn take(&mut self, c: Channel, at: &[usize], n: usize) -> Vec<f64> {
        match self.0.get_mut(c.index()).and_then(Option::take) {
            Some(s) if s.at == at && s.v.len() == n => s.v,
            _ => vec![f64::NAN; n],
        }
    }
}

impl ReplayMemo {
    /// Keeps the prediction vectors of `p`, made on the samples `s`, for the next prediction
    /// ([`Spare`]).
    pub fn recycle(&mut self, p: Predictions, s: &Samples) {
        let spare = &mut self.spare.0;
        spare.resize_with(Channel::ALL.len(), || None);
        for (c, v) in Channel::ALL.iter().zip(p.y) {
            if !v.is_empty() {
                let at = s.get(*c);
                spare[c.index()] = Some(SpareVec { at: at.to_vec(), v });
            }
        }
    }
}

/// What a prediction may take from a fit's [`ReplayMemo`] of the record and leave there.
#[derive(Default)]
struct Reuse<'a> {
    actuator: Option<&'a mut ActuatorMemo>,
    /// Only with the record's cached disk estimate ([`predict_with_disk_ref`]).
    surface: Option<&'a mut SurfaceMemo>,
    spare: Option<&'a mut Spare>,
}

/// The prediction vector of channel `c` (NaN but at `c`'s samples, which the caller writes),
/// from `spare` when given.
fn vector(spare: &mut Option<&mut Spare>, c: Channel, s: &Samples, n: usize) -> Vec<f64> {
    match spare.as_deref_mut() {
        Some(spare) => spare.take(c, s.get(c), n),
        None => vec![f64::NAN; n],
    }
}

/// The bearing positions a fit's last models replayed from the requests
/// ([`replay::actuator_replay`]), per clutch. They read only the actuator's parameters, the dead
/// time and the start position, which most columns of a Jacobian leave as they were (only an
/// actuator column moves them).
#[derive(Debug, Clone, Default)]
pub struct ActuatorMemo([Vec<(ActuatorKey, Vec<f64>)>; 2]);

/// Everything of a model and a record's start the position replay of one clutch reads (the
/// record's requests are the memo's own: one memo per record).
#[derive(Debug, Clone, Copy, PartialEq)]
struct ActuatorKey {
    actuator: ActuatorParams,
    /// The dead time's and the start position's bits (a NaN key is one key too).
    dead_time: u64,
    x0: u64,
}

impl ActuatorMemo {
    /// The positions of clutch `i` replayed from the requests `xr` (from the memo when the key is
    /// one it holds).
    fn positions(
        &mut self,
        i: usize,
        p: &ActuatorParams,
        set: &EffectSet,
        xr: &[f64],
        x0: f64,
        dt: f64,
    ) -> &[f64] {
        let key = ActuatorKey {
            actuator: *p,
            dead_time: effects::dead_time_s(set).to_bits(),
            x0: x0.to_bits(),
        };
        recall(&mut self.0[i], key, |_| {
            replay::actuator_replay(p, &delayed_requests(set, xr, dt), x0, dt)
        })
        .as_slice()
    }
}

/// Everything of a model the disk replay ([`disk::run`] under [`SetHooks::of`], on the inputs
/// [`corrected_inputs`] corrected) reads, in two parts: what the heat flows read and what β
/// reads. The torque characteristic's terms and parameters are left out: the replay is driven
/// by the measured friction power, not a predicted torque.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ReplayKey {
    heat: HeatKey,
    engagement: EngagementKey,
}

/// The thermal parameters the replay reads ([`disk::thermal_params`]), the heat effects, the
/// thermal terms and the terms that correct the inputs ([`input_key`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct HeatKey {
    thermal: [f64; 5],
    set: EffectSet,
    terms: Terms,
}

/// The clutch's engagement parameters and the engagement effects: what β reads.
#[derive(Debug, Clone, Copy, PartialEq)]
struct EngagementKey {
    clutch: [f64; 6],
    set: EffectSet,
}

impl ReplayKey {
    fn of(model: &Model) -> Self {
        let t = &model.terms;
        ReplayKey {
            heat: HeatKey {
                thermal: disk::thermal_params(&model.p.thermal5, t.partition.is_some()),
                set: model.set.only(&effects::HEAT_EFFECTS),
                terms: Terms {
                    support: t.support,
                    convection: t.convection,
                    partition: t.partition,
                    ..input_key(t)
                },
            },
            engagement: EngagementKey {
                clutch: clutch::engagement_params(&model.p.clutch),
                set: model.set.only(&effects::ENGAGEMENT_EFFECTS),
            },
        }
    }
}

/// The terms [`corrected_inputs`] reads (the others at their defaults).
fn input_key(t: &Terms) -> Terms {
    Terms {
        temp_sensor: t.temp_sensor,
        temp_lag_s: t.temp_lag_s,
        temp_lag2_share: t.temp_lag2_share,
        torque_sensor: t.torque_sensor,
        speed_sensor: t.speed_sensor,
        ..Terms::default()
    }
}

/// The entry of `v` whose key is `key`, moved to the front (computed by `make`, which sees the
/// entries kept, and put there when there is none; at most two entries kept).
fn recall<K: PartialEq, V>(v: &mut Vec<(K, V)>, key: K, make: impl FnOnce(&[(K, V)]) -> V) -> &V {
    match v.iter().position(|e| e.0 == key) {
        Some(i) => v[..=i].rotate_right(1),
        None => {
            let value = make(v);
            v.insert(0, (key, value));
            v.truncate(2);
        }
    }
    &v[0].1
}

/// The disk replay of `model` on `m` from `memo` ([`recall`]); when not there, replayed from
/// the first step where β changes against an entry that differs only in what β reads
/// ([`disk::rerun_engagement`]: a kiss-point column of a Jacobian), else from the start.
fn recall_disk<'a>(
    memo: &'a mut Vec<(ReplayKey, DiskRun)>,
    model: &Model,
    m: &Measured,
) -> &'a DiskRun {
    let key = ReplayKey::of(model);
    recall(memo, key, |kept| {
        let h = SetHooks::of(model);
        match kept.iter().find(|(k, _)| k.heat == key.heat) {
            Some((_, near)) => disk::rerun_engagement(&model.p, &h, m, near, h.heat()),
            None => disk::run_with(&model.p, &h, m, h.heat()),
        }
    })
}

/// [`predict`] reusing the corrected inputs and disk replay of `memo` when the model's keys are
/// ones it holds (the same numbers: each is a function of its key); the result's `disk` is
/// `None`.
pub fn predict_reusing(
    model: &Model,
    m: &Measured,
    s: &Samples,
    chans: &[Channel],
    memo: &mut ReplayMemo,
) -> Predictions {
    let corrected = recall(&mut memo.inputs, input_key(&model.terms), |_| {
        corrected_inputs(&model.terms, m)
    });
    let mm = corrected.as_ref().unwrap_or(m);
    if !want_torque(s, chans) {
        // No disk replay (and none in the result).
        let reuse = Reuse {
            actuator: Some(&mut memo.actuator),
            surface: None,
            spare: Some(&mut memo.spare),
        };
        return predict_inner(model, mm, s, chans, None, reuse);
    }
    let disk = recall_disk(&mut memo.disks, model, mm);
    let reuse = Reuse {
        actuator: Some(&mut memo.actuator),
        surface: None,
        spare: Some(&mut memo.spare),
    };
    predict_inner(model, mm, s, chans, Some(&*disk.theta), reuse)
}

/// [`predict`] with the disk temperature estimate given (it depends only on the thermal
/// parameters and β, so fits of the torque characteristic reuse it), the position replays from
/// `memo` when given; `disk` of the result is `None`.
pub fn predict_with_disk_ref(
    model: &Model,
    m: &Measured,
    s: &Samples,
    chans: &[Channel],
    disk: &[Vec<f64>; 2],
    memo: Option<&mut ReplayMemo>,
) -> Predictions {
    let reuse = match memo {
        Some(memo) => Reuse {
            actuator: Some(&mut memo.actuator),
            surface: Some(&mut memo.surface),
            spare: Some(&mut memo.spare),
        },
        None => Reuse::default(),
    };
    predict_inner(model, m, s, chans, Some(disk), reuse)
}

/// Whether the sensor terms change the measured inputs of the replays (a thermocouple lag or
/// reading error, a torque reading error, a speed sensor's gain or skew): then a disk estimate cached from the readings as
/// read does not hold for the model.
pub fn corrects_inputs(t: &Terms) -> bool {
    t.temp_lag_s > 0.0
        || t.temp_sensor.is_some()
        || t.torque_sensor.is_some()
        || t.speed_sensor.is_some()
}

/// Whether `chans` asks for channel `c` and `s` has samples of it.
fn wanted(s: &Samples, chans: &[Channel], c: Channel) -> bool {
    chans.contains(&c) && !s.get(c).is_empty()
}

fn want_torque(s: &Samples, chans: &[Channel]) -> bool {
    (0..2).any(|i| wanted(s, chans, Channel::Torque(i)))
}

/// The predictions of `model` on `m` with the disk replay `disk`.
fn predict_inner(
    model: &Model,
    m: &Measured,
    s: &Samples,
    chans: &[Channel],
    disk: Option<&[Vec<f64>; 2]>,
    mut reuse: Reuse<'_>,
) -> Predictions {
    let mut y = vec![Vec::new(); Channel::ALL.len()];
    if let Some(dk) = disk {
        predict_torques(model, m, s, chans, dk, &mut reuse, &mut y);
    }
    if (0..3).any(|j| wanted(s, chans, Channel::Temp(j))) {
        predict_temperatures(model, m, s, chans, &mut reuse.spare, &mut y);
    }
    predict_positions(model, m, s, chans, &mut reuse, &mut y);
    if wanted(s, chans, Channel::Engine) {
        y[Channel::Engine.index()] = predict_engine(model, m, s, &mut reuse.spare);
    }
    Predictions { y, disk: None }
}

/// The clutch torques' predictions (into `y`) with the disk replay `dk`: the torque at each
/// sample (read late by the model's torque skew, interpolated), as the torque sensor reads it.
fn predict_torques(
    model: &Model,
    m: &Measured,
    s: &Samples,
    chans: &[Channel],
    dk: &[Vec<f64>; 2],
    reuse: &mut Reuse<'_>,
    y: &mut [Vec<f64>],
) {
    let p = &model.p;
    let t = &model.terms;
    let bearing = bearing_sequence(&model.set, m);
    let surface = surface_of(model).map(|sf| {
        let make = || Arc::new(surface_temperatures(&sf, m, dk));
        match reuse.surface.as_deref_mut() {
            Some(kept) => recall_surface(kept, sf, dk, make),
            None => make(),
        }
    });
    let slide =
        t.mu.iter()
            .flatten()
            .any(|(v, _)| *v == crate::gap::model::class::Variable::SlidingAcceleration)
            .then_some(&*m.slides);
    let skew = t.torque_skew_s / m.dt;
    let shapes = m.slip_shapes(&p.clutch);
    for i in 0..2 {
        let c = Channel::Torque(i);
        if !wanted(s, chans, c) {
            continue;
        }
        let at = |k: usize| {
            torque_at(
                model,
                m,
                dk,
                bearing.as_ref(),
                surface.as_deref(),
                slide,
                &shapes,
                i,
                k,
            )
        };
        let mut v = vector(&mut reuse.spare, c, s, m.n);
        for &k in s.get(c) {
            let tq = if skew == 0.0 {
                at(k)
            } else {
                // Recorded late by the skew: the sample at k shows the torque at k − skew.
                let x = (k as f64 - skew).clamp(0.0, (m.n - 1) as f64);
                let (a, f) = (x.floor() as usize, x - x.floor());
                let b = (a + 1).min(m.n - 1);
                if f == 0.0 {
                    at(a)
                } else {
                    (1.0 - f) * at(a) + f * at(b)
                }
            };
            v[k] = t.measured_torque(tq);
        }
        y[c.index()] = v;
    }
}

/// The temperatures' predictions (into `y`): the thermal replay, lagged by the thermocouple's
/// lag, as the temperature sensor reads it.
fn predict_temperatures(
    model: &Model,
    m: &Measured,
    s: &Samples,
    chans: &[Channel],
    spare: &mut Option<&mut Spare>,
    y: &mut [Vec<f64>],
) {
    let p = &model.p;
    let h = SetHooks::of(model);
    let t = &model.terms;
    // The temperatures are read at every `stride`-th sample: the replay steps by it.
    let stride = s.temp_stride;
    let tr = crate::gap::eval::fast_replay::thermal_replay_fast(p, &h, m, stride);
    for j in 0..3 {
        let c = Channel::Temp(j);
        if !wanted(s, chans, c) {
            continue;
        }
        let mut series: Vec<f64> = tr.iter().map(|s| [s.pp1, s.pp2, s.cd][j]).collect();
        if t.temp_lag_s > 0.0 {
            series = terms::lag2(
                &series,
                t.temp_lag_s,
                t.temp_lag2_share,
                stride as f64 * m.dt,
            );
        }
        let mut v = vector(spare, c, s, m.n);
        for &k in s.get(c) {
            debug_assert_eq!(k % stride, 0, "a temperature sample off the replay's grid");
            let x = series[k / stride];
            v[k] = match &t.temp_sensor {
                Some(g) => g.apply(x),
                None => x,
            };
        }
        y[c.index()] = v;
    }
}

/// The bearing positions' predictions (into `y`) of each clutch with requests: the actuator
/// replay from the requests (the dead time's delay, from the first reading as the position
/// sensor's inverse gives it), as the position sensor reads it.
fn predict_positions(
    model: &Model,
    m: &Measured,
    s: &Samples,
    chans: &[Channel],
    reuse: &mut Reuse<'_>,
    y: &mut [Vec<f64>],
) {
    let p = &model.p;
    let t = &model.terms;
    for i in 0..2 {
        let Some(xr) = &m.x_req[i] else { continue };
        let c = Channel::Pos(i);
        if !wanted(s, chans, c) {
            continue;
        }
        let x0 = t
            .pos_sensor
            .map_or(m.x[i][0], |g| g.invert(m.x[i][0], X_REF_MM));
        let fresh;
        let xs: &[f64] = match reuse.actuator.as_deref_mut() {
            Some(memo) => memo.positions(i, &p.actuator, &model.set, xr, x0, m.dt),
            None => {
                let req = delayed_requests(&model.set, xr, m.dt);
                fresh = replay::actuator_replay(&p.actuator, &req, x0, m.dt);
                &fresh
            }
        };
        let mut v = vector(&mut reuse.spare, c, s, m.n);
        for &k in s.get(c) {
            v[k] = match &t.pos_sensor {
                Some(g) => g.apply(xs[k], X_REF_MM),
                None => xs[k],
            };
        }
        y[c.index()] = v;
    }
}

/// The engine torque's prediction: the mean real engine torque over the window
/// ([`ENGINE_WINDOW`]) through the engine map's estimate.
fn predict_engine(
    model: &Model,
    m: &Measured,
    s: &Samples,
    spare: &mut Option<&mut Spare>,
) -> Vec<f64> {
    let p = &model.p;
    let c = Channel::Engine;
    let w = ENGINE_WINDOW;
    let mut v = vector(spare, c, s, m.n);
    for &k in s.get(c) {
        // Mean real engine torque over the window: J_eq·Δω_f/Δt + mean clutch torques.
        let dw = m.w_f[k + w] - m.w_f[k];
        let real = p.driveline.j_eq_kgm2 * dw / (w as f64 * m.dt)
            + window_mean(&m.torque[0], k)
            + window_mean(&m.torque[1], k);
        v[k] = effects::engine_map_estimate(&model.set, real);
    }
    v
}

/// Residuals (measured − predicted) of the channels at their samples, in channel order.
pub fn residuals(
    m: &Measured,
    s: &Samples,
    pred: &Predictions,
    chans: &[Channel],
    out: &mut Vec<f64>,
) {
    for &c in chans {
        let y = &pred.y[c.index()];
        for &k in s.get(c) {
            out.push(measured(m, c, k) - y[k]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Params;

    use crate::gap::record::measured::test_record as record;

    fn same(a: &Predictions, b: &Predictions) {
        for (x, y) in a.y.iter().zip(&b.y) {
            assert_eq!(x.len(), y.len());
            for (u, v) in x.iter().zip(y) {
                assert!(u.to_bits() == v.to_bits(), "{u} != {v}");
            }
        }
    }

    /// A fit's sequence of models — a torque term moved (the replay reused), a thermal parameter
    /// moved (replayed again), a torque reading error (the inputs corrected), back to the first
    /// point — predicts bit for bit what [`predict`] does from scratch, and the memo holds two
    /// replays at most.
    #[test]
    fn reused_replays_predict_what_a_fresh_replay_does() {
        let p = Params::default();
        let m = record(&p);
        let s = Samples::new(&m, 1, 10);
        assert!(!s.get(Channel::Torque(0)).is_empty());
        let chans = Channel::ALL;
        let base = Model::nominal(p);
        let mut torque = base;
        torque.terms.torque_skew_s = 0.02;
        let mut thermal = base;
        thermal.p.thermal5.alpha7_k_per_j *= 1.2;
        let mut sensor = base;
        sensor.terms.torque_sensor = Some(terms::GainOffset {
            gain: 1.05,
            offset: 2.0,
        });
        let mut memo = ReplayMemo::default();
        let mut replays = 0;
        // Kiss-point columns: replayed from where β first changes (a step too small to change
        // it reuses the replay whole).
        let mut kiss = base;
        kiss.p.clutch.x_isp0_mm += 0.3;
        let mut tiny = base;
        tiny.p.clutch.x_isp0_mm *= 1.0 + 1e-9;
        for model in [base, kiss, tiny, base] {
            let fresh = predict(&model, &m, &s, &chans);
            let kept = predict_reusing(&model, &m, &s, &chans, &mut memo);
            same(&kept, &fresh);
            // The next prediction writes into these vectors: NaN where it does not evaluate.
            memo.recycle(kept, &s);
        }
        let mut memo = ReplayMemo::default();
        for model in [base, torque, thermal, sensor, base, torque] {
            let fresh = predict(&model, &m, &s, &chans);
            let before = memo.disks.first().map(|e| e.0);
            let kept = predict_reusing(&model, &m, &s, &chans, &mut memo);
            same(&kept, &fresh);
            memo.recycle(kept, &s);
            replays += usize::from(before != memo.disks.first().map(|e| e.0) || before.is_none());
            assert!(memo.disks.len() <= 2 && memo.inputs.len() <= 2);
        }
        // base, thermal, sensor, base again (evicted by the two before it); torque reuses.
        assert_eq!(replays, 4);
        // The thermal change does move the disk replay (the memo is not returning a stale one).
        let a = predict(&base, &m, &s, &chans).disk.unwrap();
        let b = predict(&thermal, &m, &s, &chans).disk.unwrap();
        assert!(a[0].iter().zip(&b[0]).any(|(x, y)| (x - y).abs() > 1e-3));
    }

    /// A record whose speed channels read 4 % high predicts, with a speed-sensor term of gain
    /// 1.04, what the record of the true speeds predicts without one (to rounding): the slip,
    /// the flywheel speed and the friction power are corrected before the replays. Without
    /// the term the temperatures are off by kelvins.
    #[test]
    fn a_speed_sensor_term_undoes_the_speed_channels_gain() {
        let p = Params::default();
        let m = record(&p);
        let read = |v: &Shared| -> Shared { v.iter().map(|w| 1.04 * w).collect() };
        let high = m
            .clone()
            .with_speeds([read(&m.slip[0]), read(&m.slip[1])], read(&m.w_f));
        let power: [Shared; 2] = [0, 1]
            .map(|i| -> Shared { (0..m.n).map(|k| m.torque[i][k] * high.slip[i][k]).collect() });
        let e_cum =
            [0, 1].map(|i| -> Shared { series::cumulative_energy(&power[i], m.e_cum[i][0], m.dt) });
        let high = high.with_power(power, e_cum);
        let s = Samples::new(&m, 1, 10);
        let chans = Channel::ALL;
        let base = Model::nominal(p);
        let mut corrected = base;
        corrected.terms.speed_sensor = Some(terms::SpeedSensor {
            gain: 1.04,
            skew_s: 0.0,
        });
        let truth = predict(&base, &m, &s, &chans);
        let fixed = predict(&corrected, &high, &s, &chans);
        let wrong = predict(&base, &high, &s, &chans);
        let largest = |a: &Predictions, b: &Predictions, c: Channel| {
            let (x, y) = (&a.y[c.index()], &b.y[c.index()]);
            assert_eq!(x.len(), y.len());
            x.iter()
                .zip(y)
                .filter(|(u, v)| u.is_finite() && v.is_finite())
                .map(|(u, v)| (u - v).abs())
                .fold(0.0, f64::max)
        };
        for c in [Channel::Temp(0), Channel::Temp(2), Channel::Torque(0)] {
            assert!(!truth.y[c.index()].is_empty(), "{c:?} not predicted");
            let d = largest(&fixed, &truth, c);
            assert!(d < 1e-6, "{c:?}: corrected prediction off by {d}");
        }
        let off = largest(&wrong, &truth, Channel::Temp(0));
        assert!(
            off > 0.5,
            "the gain moves the plate temperature by {off} K only"
        );
    }

    /// On the record's cached disk estimate, a fit's models — a surface term, the term moved, a
    /// torque parameter moved (the kept surface temperatures reused), back — predict bit for bit
    /// what they predict without a memo; vectors kept from other samples are not taken.
    #[test]
    fn kept_surface_temperatures_and_vectors_predict_what_fresh_ones_do() {
        let p = Params::default();
        let m = record(&p);
        let (s, other) = (Samples::new(&m, 1, 10), Samples::new(&m, 3, 10));
        assert_ne!(s.get(Channel::Torque(0)), other.get(Channel::Torque(0)));
        let chans = Channel::ALL;
        let base = Model::nominal(p);
        let disk = predict(&base, &m, &s, &chans).disk.unwrap();
        let z = std::array::from_fn(|j| j as f64 * 5e3);
        let mut hot = base;
        hot.terms.surface = Some(Surface {
            rise: Shape {
                z,
                v: z.map(|w| 0.02 * w),
            },
            tau_s: 0.2,
        });
        // The member switches the facing temperatures over to the surface's (as the class does).
        hot.set.set_clamped(
            EffectId::SurfaceTemperatureFriction,
            &hot.terms.surface.unwrap().member(),
        );
        let mut hotter = hot;
        if let Some(sf) = hotter.terms.surface.as_mut() {
            sf.rise.v = sf.rise.v.map(|v| 2.0 * v);
        }
        let mut friction = hot;
        friction.p.clutch.c4 *= 1.1;
        let mut memo = ReplayMemo::default();
        for (model, on) in [
            (hot, &s),
            (hotter, &s),
            (friction, &s),
            (hot, &other),
            (hot, &s),
        ] {
            let fresh = predict_with_disk_ref(&model, &m, on, &chans, &disk, None);
            let kept = predict_with_disk_ref(&model, &m, on, &chans, &disk, Some(&mut memo));
            same(&kept, &fresh);
            assert!(memo.surface.len() <= 2);
            memo.recycle(kept, on);
        }
        // The surface term moves the torque (the memo is not returning stale temperatures).
        let a = predict_with_disk_ref(&hot, &m, &s, &chans, &disk, None);
        let b = predict_with_disk_ref(&hotter, &m, &s, &chans, &disk, None);
        let t = Channel::Torque(0).index();
        assert!(a.y[t]
            .iter()
            .zip(&b.y[t])
            .any(|(x, y)| (x - y).abs() > 1e-3));
    }

    /// The position replays a memo keeps: a lag, a dead time and a position reading error moved
    /// in turn, each model's positions bit for bit a fresh prediction's, from the memo (two
    /// entries per clutch) when only the torque moved, and each move does move them.
    #[test]
    fn kept_position_replays_are_a_fresh_replays() {
        let p = Params::default();
        let m = record(&p);
        let s = Samples::new(&m, 1, 10);
        let pos = Channel::Pos(0);
        assert!(m.x_req[0].is_some() && !s.get(pos).is_empty());
        let chans = [Channel::Torque(0), pos];
        let base = Model::nominal(p);
        let mut lag = base;
        lag.p.actuator.tau_s *= 1.3;
        let mut dead = base;
        dead.set.set(EffectId::ActuatorDeadTime, &[0.03]).unwrap();
        let mut sensor = base;
        sensor.terms.pos_sensor = Some(terms::GainOffset {
            gain: 1.02,
            offset: 0.1,
        });
        let mut torque = base;
        torque.terms.torque_skew_s = 0.02;
        let mut memo = ReplayMemo::default();
        let at = |pr: &Predictions| {
            s.get(pos)
                .iter()
                .map(|&k| pr.y[pos.index()][k])
                .collect::<Vec<_>>()
        };
        let first = at(&predict(&base, &m, &s, &chans));
        for model in [base, lag, torque, dead, sensor, base, lag] {
            let fresh = predict(&model, &m, &s, &chans);
            same(&predict_reusing(&model, &m, &s, &chans, &mut memo), &fresh);
            assert!(memo.actuator.0.iter().all(|v| v.len() <= 2));
            let moved = at(&fresh)
                .iter()
                .zip(&first)
                .any(|(a, b)| (a - b).abs() > 1e-4);
            assert_eq!(
                moved,
                model != base && model != torque,
                "{:?}",
                model.terms.pos_sensor
            );
        }
    }

    /// Two records of equal contents in different allocations predict the same numbers, bit for
    /// bit, whichever is evaluated first and however often: nothing kept is keyed by where a
    /// record or a sample set lives (a surface term, the slip shapes and the windowed thermal
    /// replay all read their memos).
    #[test]
    fn equal_records_in_other_allocations_predict_the_same_in_either_order() {
        let p = Params::default();
        let mut model = Model::nominal(p);
        let z = std::array::from_fn(|j| j as f64 * 5e3);
        model.terms.surface = Some(Surface {
            rise: Shape {
                z,
                v: z.map(|w| 0.02 * w),
            },
            tau_s: 0.2,
        });
        let chans = Channel::ALL;
        let run = |first: &Measured, second: &Measured| {
            [first, second, first].map(|m| {
                let s = Samples::new(m, 1, 10);
                predict(&model, m, &s, &chans).y
            })
        };
        let (a, b) = (record(&p), record(&p));
        assert!(!Arc::ptr_eq(&a.power[0], &b.power[0]));
        let bits =
            |y: &[Vec<f64>]| -> Vec<u64> { y.iter().flatten().map(|v| v.to_bits()).collect() };
        let ab = run(&a, &b);
        let (c, d) = (record(&p), record(&p));
        let dc = run(&d, &c);
        for y in ab.iter().chain(&dc) {
            assert_eq!(bits(y), bits(&ab[0]));
        }
        assert!(ab[0].iter().any(|v| v.iter().any(|x| x.is_finite())));
    }
}

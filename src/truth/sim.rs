//! The truth's rig simulator: the physics of [`super::physics`] with the injected effects of
//! [`super::inject`], integrated by Heun's method (explicit trapezoid) at 1 ms — deliberately not
//! the diagnosis's RK4 at 10 ms — sampled every 10 ms, with sensors (lag, gain/offset, skew),
//! then noise and quantisation in a separate pass ([`measure`]).

use super::experiments::{RecordDef, SAMPLE_S};
use super::inject::{self, Effect, OutsideKind, ReadingError, Target};
use super::physics::Physics;
use super::rng::{derive, Xoshiro};
use crate::gap::model::class::ClassId;

/// Integration step (s).
pub const STEP_S: f64 = 0.001;
/// Integration steps per sample.
pub const SUB: usize = 10;

/// Sampled channels of a record (the documented CSV columns).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Signals {
    pub time: Vec<f64>,
    /// Measured bearing (actuator) positions x_to1, x_to2 (mm).
    pub x: [Vec<f64>; 2],
    /// Input (dyno) speed ω_f (rad/s).
    pub wf: Vec<f64>,
    /// Clutch (output) speeds ω_c1, ω_c2 (rad/s): braked.
    pub wc: [Vec<f64>; 2],
    /// Output shaft speed (rad/s): braked.
    pub wout: Vec<f64>,
    pub torque: [Vec<f64>; 2],
    pub pp: [Vec<f64>; 2],
    pub cd: Vec<f64>,
    pub th: Vec<f64>,
    /// Position requests (mm) as logged.
    pub xreq: [Vec<f64>; 2],
}

impl Signals {
    pub fn len(&self) -> usize {
        self.time.len()
    }
    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }
}

/// A simulated record with the bookkeeping the tests check.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOut {
    pub signals: Signals,
    /// True (noise-free, sensor-free) temperatures at the samples: pp1, pp2, c1, c2, cd.
    pub true_temps: Vec<[f64; 5]>,
    /// Friction energy of each clutch at the end, counted from `e0` (J).
    pub e_end: [f64; 2],
    /// ∫ (P1 + P2) dt from the 1 ms torques (trapezoid) (J).
    pub friction_work_j: f64,
    /// Heat lost to the housing air and the supports (J).
    pub heat_lost_j: f64,
}

/// Sensor noise (σ) and quantisation steps.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Noise {
    pub torque_nm: f64,
    pub temp_c: f64,
    pub pos_mm: f64,
    pub speed_rpm: f64,
    pub q_torque_nm: f64,
    pub q_temp_c: f64,
    pub q_pos_mm: f64,
}

impl Default for Noise {
    fn default() -> Self {
        Noise {
            torque_nm: 0.5,
            temp_c: 0.3,
            pos_mm: 0.002,
            speed_rpm: 0.5,
            q_torque_nm: 0.1,
            q_temp_c: 0.1,
            q_pos_mm: 0.001,
        }
    }
}

/// Exact update of a first-order lag τ·ẏ = u − y over a step `h` with the input held.
#[inline]
pub fn lag_step(y: f64, u: f64, h: f64, tau: f64) -> f64 {
    Lag::new(h, tau).step(y, u)
}

/// [`lag_step`] for a fixed step and time constant, its exponential taken once.
#[derive(Debug, Clone, Copy)]
pub struct Lag(Option<f64>);

impl Lag {
    pub fn new(h: f64, tau: f64) -> Self {
        Lag((tau > 0.0).then(|| (-h / tau).exp()))
    }

    #[inline]
    pub fn step(self, y: f64, u: f64) -> f64 {
        match self.0 {
            Some(a) => u + (y - u) * a,
            None => u,
        }
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct State {
    xa: [f64; 2],
    /// pp1, pp2, c1, c2, cd (°C).
    th: [f64; 5],
    e: [f64; 2],
    flash: [f64; 2],
    loss: f64,
}

impl State {
    fn axpy(&self, k: f64, d: &State) -> State {
        let mut s = *self;
        for i in 0..2 {
            s.xa[i] += k * d.xa[i];
            s.e[i] += k * d.e[i];
            s.flash[i] += k * d.flash[i];
        }
        for j in 0..5 {
            s.th[j] += k * d.th[j];
        }
        s.loss += k * d.loss;
        s
    }
}

/// States outside the ODE, updated after each step.
#[derive(Debug, Clone, Copy, Default)]
struct Discrete {
    /// Bearing positions behind the play (mm).
    xb: [f64; 2],
    /// Time since each clutch closed (s).
    t_eng: [f64; 2],
    /// Thermocouples of pp1, pp2, cd.
    tc: [[f64; 2]; 3],
    /// Friction drift (relative).
    drift: f64,
}

#[derive(Debug, Clone, Copy, Default)]
struct Out {
    torque: [f64; 2],
    beta: [bool; 2],
    /// The dyno speed at the derivative's time (rad/s).
    w: f64,
}

/// The active effects, resolved once.
#[derive(Default)]
struct Fx<'a> {
    mu_temp: Option<&'a Effect>,
    mu_s_temp: Option<&'a Effect>,
    mu_slip: Option<&'a Effect>,
    mu_clamp: Option<&'a Effect>,
    mu_energy: Option<&'a Effect>,
    flash: Option<&'a Effect>,
    facing: f64,
    spring_temp: Option<&'a Effect>,
    kiss_temp: Option<&'a Effect>,
    kiss_energy: Option<&'a Effect>,
    dead_time: f64,
    lag_factor: f64,
    backlash: f64,
    transfer: ReadingError<'a>,
    support: Option<&'a Effect>,
    conv: Option<&'a Effect>,
    partition: Option<&'a Effect>,
    s_torque: ReadingError<'a>,
    /// Torque channel: pure delay and first-order filter time constant.
    skew: f64,
    torque_filter: f64,
    /// Thermocouples: a transport delay (s), then two first-order lags in series.
    tc_delay: f64,
    tc_lag: [f64; 2],
    s_temp: ReadingError<'a>,
    s_pos: ReadingError<'a>,
    /// Speed channels: relative gain error and time skew (s).
    speed_gain_error: f64,
    speed_skew: f64,
    judder: Option<&'a Effect>,
    drift: Option<&'a Effect>,
    cross: Option<&'a Effect>,
    eng_time: Option<&'a Effect>,
    drag: Option<&'a Effect>,
    /// Share of the disk-to-central-disk conduction taken from the central disk instead.
    flipped: f64,
}

impl<'a> Fx<'a> {
    fn new(effects: &'a [Effect]) -> Fx<'a> {
        let reading = |e: &'a Effect| match e.target {
            Target::Class(c) => inject::reading_reference(c)
                .map_or_else(ReadingError::default, |(v0, v_ref)| {
                    e.reading_error(v0, v_ref)
                }),
            Target::Outside(_) => ReadingError::default(),
        };
        let mut f = Fx {
            lag_factor: 1.0,
            ..Fx::default()
        };
        for e in effects {
            use ClassId as C;
            match e.target {
                Target::Class(c) => match c {
                    C::FrictionTemperature => f.mu_temp = Some(e),
                    C::FrictionStaticTemperature => f.mu_s_temp = Some(e),
                    C::FrictionSlip => f.mu_slip = Some(e),
                    C::FrictionClampLoad => f.mu_clamp = Some(e),
                    C::FrictionEnergy => f.mu_energy = Some(e),
                    C::FrictionSurfaceTemperature => f.flash = Some(e),
                    C::FacingTemperature => f.facing = e.magnitude.clamp(0.0, 1.0),
                    C::SpringTemperature => f.spring_temp = Some(e),
                    C::KissPointTemperature => f.kiss_temp = Some(e),
                    C::KissPointEnergy => f.kiss_energy = Some(e),
                    C::ActuatorDeadTime => f.dead_time = e.magnitude.max(0.0),
                    C::ActuatorLag => {
                        let k = e.magnitude.max(1.0);
                        f.lag_factor = if e.aux("faster") > 0.5 { 1.0 / k } else { k };
                    }
                    C::ActuatorBacklash => f.backlash = e.magnitude.max(0.0),
                    C::ActuatorTransfer => f.transfer = reading(e),
                    C::SupportConduction => f.support = Some(e),
                    C::ConvectionSpeed => f.conv = Some(e),
                    C::HeatPartition => f.partition = Some(e),
                    C::SensorTorque => f.s_torque = reading(e),
                    C::SensorTorqueSkew => {
                        let q = if e.magnitude > 0.0 {
                            e.aux("filter_share")
                        } else {
                            0.0
                        };
                        f.torque_filter = q * e.magnitude;
                        f.skew = e.magnitude - f.torque_filter;
                    }
                    C::SensorTemperatureLag => {
                        let m = e.magnitude.max(0.0);
                        let s = e.aux("first_share");
                        let delay = e.aux("delay_share") * m;
                        f.tc_delay = delay;
                        f.tc_lag = [s * (m - delay), (1.0 - s) * (m - delay)];
                    }
                    C::SensorTemperature => f.s_temp = reading(e),
                    C::SensorPosition => f.s_pos = reading(e),
                    C::SensorSpeed => {
                        f.speed_gain_error = e.magnitude;
                        f.speed_skew = e.aux("skew_s");
                    }
                    _ => {}
                },
                Target::Outside(o) => match o {
                    OutsideKind::Judder => f.judder = Some(e),
                    OutsideKind::FrictionDrift => f.drift = Some(e),
                    OutsideKind::CrossClutch => f.cross = Some(e),
                    OutsideKind::EngagementTime => f.eng_time = Some(e),
                    OutsideKind::OpenDrag => f.drag = Some(e),
                    OutsideKind::ConductionSign => f.flipped = e.magnitude.clamp(0.0, 1.0),
                },
            }
        }
        f
    }
}

/// The multiplier (1 + term) of an active effect at its variable's z (taken only when the effect
/// is active: z may cost a logarithm), 1 without it.
#[inline]
fn mult(e: Option<&Effect>, z: impl FnOnce() -> f64) -> f64 {
    match e {
        Some(e) => (1.0 + e.term(z())).max(0.0),
        None => 1.0,
    }
}

/// The shift (term) of an active effect at its variable's z, 0 without it.
#[inline]
fn shift(e: Option<&Effect>, z: impl FnOnce() -> f64) -> f64 {
    match e {
        Some(e) => e.term(z()),
        None => 0.0,
    }
}

struct Rig<'a> {
    ph: &'a Physics,
    rec: &'a RecordDef,
    fx: Fx<'a>,
    /// Q(ω) cache per clutch: (ω, Q).
    q_cache: [(f64, f64); 2],
    /// The dyno speed's knot of the last call ([`RecordDef::speed_radps_from`]).
    speed_hint: usize,
}

impl<'a> Rig<'a> {
    /// The rig of record `rec` under the `effects`.
    fn new(ph: &'a Physics, rec: &'a RecordDef, effects: &'a [Effect]) -> Self {
        Rig {
            ph,
            rec,
            fx: Fx::new(effects),
            q_cache: [(f64::NAN, 0.0); 2],
            speed_hint: 0,
        }
    }

    fn q(&mut self, i: usize, w: f64) -> f64 {
        if self.q_cache[i].0 != w {
            self.q_cache[i] = (w, self.ph.q_slip(w));
        }
        self.q_cache[i].1
    }

    /// Bearing position seen by clutch i for actuator position xa.
    #[inline]
    fn bearing(&self, i: usize, xa: f64, d: &Discrete) -> f64 {
        let b = self.fx.backlash;
        let x = if b > 0.0 {
            d.xb[i].clamp(xa - 0.5 * b, xa + 0.5 * b)
        } else {
            xa
        };
        self.fx.transfer.read(x)
    }

    /// Derivative of the state at time `t` with the actuator requests `r`.
    fn deriv(&mut self, s: &State, t: f64, r: [f64; 2], d: &Discrete) -> (State, Out) {
        let w = self.rec.speed_radps_from(t, &mut self.speed_hint);
        let th_h = self.rec.housing_c(t);
        // Clamp loads first (the cross-clutch effect needs the other one).
        let mut force = [0.0; 2];
        let mut beta = [false; 2];
        for i in 0..2 {
            (force[i], beta[i]) = self.clamp_load(i, s, d);
        }
        let mut torque = [0.0; 2];
        let mut ds = State::default();
        for i in 0..2 {
            if force[i] > 0.0 && w != 0.0 {
                torque[i] = self.friction_torque(i, s, t, d, w, force);
            } else if let (Some(e), true) = (self.fx.drag, w != 0.0) {
                torque[i] = self.drag_torque(e, i, s, d, w);
            }
            // Flash temperature: first order towards its steady value at this power.
            if let Some(e) = self.fx.flash {
                let p = (torque[i] * w).max(0.0);
                let target = e.magnitude * e.form.eval(inject::z_power(p));
                ds.flash[i] = (target - s.flash[i]) / e.aux("tau_s");
            }
        }
        self.thermal_rates(s, th_h, w, torque, beta, &mut ds);
        for (i, &request) in r.iter().enumerate() {
            ds.xa[i] = self
                .ph
                .actuator_rate(s.xa[i], request, self.ph.tau * self.fx.lag_factor);
        }
        (ds, Out { torque, beta, w })
    }

    /// Clutch `i`'s clamp load and whether the diaphragm spring is compressed (β): the kiss point
    /// shifted by temperature and energy, the spring's load lost with temperature
    /// (1 − a·f(z), or 1 + a·(1 − f(z))).
    #[inline]
    fn clamp_load(&self, i: usize, s: &State, d: &Discrete) -> (f64, bool) {
        let (ph, fx) = (self.ph, &self.fx);
        let tc = s.th[2 + i];
        let xb = self.bearing(i, s.xa[i], d);
        let ke = shift(fx.kiss_energy, || inject::z_energy(s.e[i]));
        let kiss = ph.kiss(tc) + shift(fx.kiss_temp, || inject::z_temp(tc)) + ke;
        let u = ph.compression(xb, kiss, ph.x_max + ke);
        let force = ph.spring(u) * (1.0 - shift(fx.spring_temp, || inject::z_temp(tc))).max(0.0);
        (force, u > 0.0)
    }

    /// Clutch `i`'s friction torque at slip `w` under the clamp loads `force`: the friction
    /// radius of both faces (their temperatures pulled toward the neighbouring plates by the
    /// facing effect, plus the flash temperature) times every friction effect's multiplier, the
    /// engagement-time decay, the drift and the judder.
    #[inline]
    fn friction_torque(
        &mut self,
        i: usize,
        s: &State,
        t: f64,
        d: &Discrete,
        w: f64,
        force: [f64; 2],
    ) -> f64 {
        let ph = self.ph;
        let tc = s.th[2 + i];
        let f = force[i];
        let fx = &self.fx;
        let mu_s = ph.mu_s * mult(fx.mu_s_temp, || inject::z_temp(tc));
        let (pp, cd) = (s.th[i], s.th[4]);
        let (th1, th2) = if fx.facing > 0.0 {
            (tc + fx.facing * (pp - tc), tc + fx.facing * (cd - tc))
        } else {
            (tc, tc)
        };
        let fl = s.flash[i];
        let m = mult(fx.mu_temp, || inject::z_temp(tc))
            * mult(fx.mu_slip, || inject::z_slip(w))
            * mult(fx.mu_clamp, || inject::z_clamp(f))
            * mult(fx.mu_energy, || inject::z_energy(s.e[i]))
            * mult(fx.cross, || inject::z_clamp(force[1 - i]))
            * match fx.eng_time {
                Some(e) => (1.0 + e.magnitude * (-d.t_eng[i] / e.aux("tau_s")).exp()).max(0.0),
                None => 1.0,
            }
            * (1.0 + d.drift).max(0.0);
        let jud = match fx.judder {
            Some(e) => {
                1.0 + e.magnitude
                    * (std::f64::consts::TAU * e.aux("freq_hz") * t + e.aux("phase_rad") + i as f64)
                        .sin()
            }
            None => 1.0,
        };
        let q = self.q(i, w);
        let r1 = ph.r_mu_q(q, mu_s, ph.mu_dyn(th1 + fl));
        let r_mu = if th1 == th2 {
            r1 + r1
        } else {
            r1 + ph.r_mu_q(q, mu_s, ph.mu_dyn(th2 + fl))
        };
        w.signum() * r_mu * f * m * jud
    }

    /// Drag of the open clutch `i` (effect `e`): air and residual contact, growing with speed
    /// and towards the kiss point (30 % of it fully open).
    #[inline]
    fn drag_torque(&self, e: &Effect, i: usize, s: &State, d: &Discrete, w: f64) -> f64 {
        let xb = self.bearing(i, s.xa[i], d);
        let gap = (self.ph.kiss(s.th[2 + i]) - xb).max(0.0);
        w.signum()
            * e.magnitude
            * e.form.eval(inject::z_speed(w))
            * (0.3 + 0.7 * (-gap / 1.0).exp())
    }

    /// The thermal model in its physical form: the five temperatures' rates, the friction
    /// energies' rates and the heat lost to the balance, into `ds` (convection by speed,
    /// conduction to the support, the heat partition and the conduction sign effects included).
    #[inline]
    fn thermal_rates(
        &self,
        s: &State,
        th_h: f64,
        w: f64,
        torque: [f64; 2],
        beta: [bool; 2],
        ds: &mut State,
    ) {
        let (ph, fx) = (self.ph, &self.fx);
        let conv = mult(fx.conv, || inject::z_speed(w));
        let support = |theta: f64, c: f64, weight: f64| -> f64 {
            match fx.support {
                Some(e) if weight > 0.0 => {
                    let dz = (theta - th_h) / 280.0;
                    dz.signum() * e.magnitude * weight * c * 280.0 * e.form.eval(dz.abs())
                }
                _ => 0.0,
            }
        };
        let (w_pp, w_c, w_cd) = match fx.support {
            Some(e) => (e.aux("w_pp"), e.aux("w_c"), e.aux("w_cd")),
            None => (0.0, 0.0, 0.0),
        };
        let mut q_cd = 0.0;
        let mut loss = 0.0;
        for i in 0..2 {
            let b = if beta[i] { 1.0 } else { 0.0 };
            let p = torque[i] * w;
            let (mut phi_pp, mut phi_c) = (ph.phi_pp, ph.phi_c);
            if let Some(e) = fx.partition {
                let moved = ph.phi_pp * e.magnitude * e.form.eval(inject::z_power(p.abs()));
                phi_pp -= moved;
                phi_c += moved;
            }
            let (pp, c, cd) = (s.th[i], s.th[2 + i], s.th[4]);
            let conv_pp = (1.0 - b) * ph.h_pp * conv * (th_h - pp);
            let conv_c = (1.0 - b) * ph.h_c * conv * (th_h - c);
            let sup_pp = support(pp, ph.c_pp, w_pp);
            let sup_c = support(c, ph.c_c, w_c);
            let q_pc = b * ph.g_pc * (c - pp);
            let q_ccd = b * ph.g_ccd * (c - cd);
            ds.th[i] = (q_pc + conv_pp + phi_pp * p - sup_pp) / ph.c_pp;
            ds.th[2 + i] = (-q_pc - q_ccd + conv_c + phi_c * p - sup_c) / ph.c_c;
            // With the sign flipped for a share, that share leaves the central disk too (and
            // the heat it would have carried is lost to the balance).
            q_cd += (1.0 - 2.0 * fx.flipped) * q_ccd + ph.phi_cd * p;
            loss += -conv_pp - conv_c + sup_pp + sup_c + 2.0 * fx.flipped * q_ccd;
            ds.e[i] = p;
        }
        let nb = beta.iter().filter(|b| !**b).count() as f64;
        let conv_cd = nb * ph.h_cd * conv * (th_h - s.th[4]);
        let sup_cd = support(s.th[4], ph.c_cd, w_cd);
        ds.th[4] = (q_cd + conv_cd - sup_cd) / ph.c_cd;
        loss += -conv_cd + sup_cd;
        ds.loss = loss;
    }
}

/// Simulates one record. `e0`: friction energy of each clutch at the start (J) (a worn pack);
/// `seed` drives the effects' own randomness (the friction drift), not the sensor noise.
pub fn simulate(
    ph: &Physics,
    effects: &[Effect],
    rec: &RecordDef,
    e0: [f64; 2],
    seed: u64,
) -> SimOut {
    simulate_with(ph, effects, rec, e0, seed, SUB)
}

/// [`simulate`] with `sub` integration steps per sample (a step of [`STEP_S`]·[`SUB`]/`sub`):
/// a coarser step for the sensitivities of [`super::identifiable`].
pub fn simulate_with(
    ph: &Physics,
    effects: &[Effect],
    rec: &RecordDef,
    e0: [f64; 2],
    seed: u64,
    sub: usize,
) -> SimOut {
    let sub = sub.max(1);
    let mut rig = Rig::new(ph, rec, effects);
    let n = rec.samples();
    let steps = (n - 1) * sub;
    let mut s = State {
        th: [rec.theta0_c; 5],
        e: e0,
        ..State::default()
    };
    let mut d = Discrete {
        tc: [[rec.theta0_c; 2]; 3],
        ..Discrete::default()
    };
    let mut drift = rig.fx.drift.map(|e| Drift::new(e, seed));
    if let Some(dr) = drift.as_mut() {
        d.drift = dr.start();
    }
    let mut t_ms: [Vec<f64>; 2] = [Vec::with_capacity(steps + 1), Vec::with_capacity(steps + 1)];
    let mut sig = Signals::default();
    let mut true_temps = Vec::with_capacity(n);
    let mut work = 0.0;
    let mut p_prev = 0.0;
    // Exactly STEP_S at the default `sub`.
    let h = STEP_S * (SUB as f64 / sub as f64);
    let mut tcs = ThermocouplePath::new(&rig.fx, h, rec.theta0_c);
    let dead = rig.fx.dead_time;
    let mut held = (f64::NAN, [0.0; 2]);
    for j in 0..=steps {
        let t = j as f64 * h;
        let tm = t + 0.5 * h - dead;
        let r = rec.requests_held(tm.max(-1.0), &mut held);
        let r = if tm < 0.0 { [0.0; 2] } else { r };
        let (k1, out) = rig.deriv(&s, t, r, &d);
        t_ms[0].push(out.torque[0]);
        t_ms[1].push(out.torque[1]);
        let w = out.w;
        let p = (out.torque[0] + out.torque[1]) * w;
        if j > 0 {
            work += 0.5 * (p + p_prev) * h;
        }
        p_prev = p;
        if j % sub == 0 {
            sig.push_sample(rec, &rig.fx, (j / sub) as f64 * SAMPLE_S, &s, &d, w);
            true_temps.push(s.th);
        }
        if j == steps {
            break;
        }
        let sp = s.axpy(h, &k1);
        let (k2, _) = rig.deriv(&sp, t + h, r, &d);
        s = s.axpy(0.5 * h, &k1).axpy(0.5 * h, &k2);
        d.advance(&s, &out, h, rig.fx.backlash, &mut tcs);
        if let Some(dr) = drift.as_mut() {
            if (j + 1) % sub == 0 {
                d.drift = dr.next(d.drift);
            }
        }
    }
    sig.torque = torque_channel(&rig.fx, &mut t_ms, n, sub, h);
    thermocouple_reading(rig.fx.s_temp, &mut sig);
    speed_channels(&rig.fx, rec, &mut sig);
    SimOut {
        signals: sig,
        true_temps,
        e_end: s.e,
        friction_work_j: work,
        heat_lost_j: s.loss,
    }
}

impl Signals {
    /// One sample at `tk` of the state `s` (discrete states `d`, dyno speed `w`): positions read
    /// through the position sensor, the requests, the thermocouples, the housing.
    fn push_sample(&mut self, rec: &RecordDef, fx: &Fx, tk: f64, s: &State, d: &Discrete, w: f64) {
        self.time.push(tk);
        for i in 0..2 {
            self.x[i].push(fx.s_pos.read(s.xa[i]));
            self.wc[i].push(0.0);
            self.xreq[i].push(rec.request(i, tk));
            self.pp[i].push(d.tc[i][1]);
        }
        self.cd.push(d.tc[2][1]);
        self.wf.push(w);
        self.wout.push(0.0);
        self.th.push(rec.housing_c(tk));
    }
}

/// What the thermocouples of pp1, pp2 and cd see of their true temperatures: a delay line of
/// `tc_delay` (the pack at rest before t = 0), then two first-order lags.
struct ThermocouplePath {
    seen: [std::collections::VecDeque<f64>; 3],
    lags: [Lag; 2],
}

impl ThermocouplePath {
    /// The path of the effects `fx` at the integration step `h`, the pack at `theta0_c` before.
    fn new(fx: &Fx, h: f64, theta0_c: f64) -> Self {
        let delay_steps = (fx.tc_delay / h).round() as usize;
        ThermocouplePath {
            seen: std::array::from_fn(|_| {
                std::collections::VecDeque::from(vec![theta0_c; delay_steps])
            }),
            lags: fx.tc_lag.map(|tau| Lag::new(h, tau)),
        }
    }
}

/// The friction drift: a first-order random process (stationary standard deviation
/// `magnitude`, time constant `tau_s`) sampled every [`SAMPLE_S`] from the effect's own stream.
struct Drift<'a> {
    e: &'a Effect,
    rng: Xoshiro,
}

impl<'a> Drift<'a> {
    /// The drift of effect `e` in the record of `seed`.
    fn new(e: &'a Effect, seed: u64) -> Self {
        Drift {
            e,
            rng: Xoshiro::new(derive(seed, &[e.aux("seed") as u64])),
        }
    }

    /// The value at the start (a draw of the stationary distribution).
    fn start(&mut self) -> f64 {
        self.e.magnitude * self.rng.normal()
    }

    /// The value a sample after `x`.
    fn next(&mut self, x: f64) -> f64 {
        let a = (-SAMPLE_S / self.e.aux("tau_s")).exp();
        x * a + self.e.magnitude * (1.0 - a * a).sqrt() * self.rng.normal()
    }
}

impl Discrete {
    /// The discrete states after a step `h` to `s` (the step's start gave `out`): the bearing
    /// behind the play `backlash`, the time each clutch has been closed, and the thermocouples —
    /// each sees its true temperature through the delay line, then the two lags (`tcs`).
    fn advance(&mut self, s: &State, out: &Out, h: f64, backlash: f64, tcs: &mut ThermocouplePath) {
        let ThermocouplePath {
            seen,
            lags: tc_lags,
        } = tcs;
        for i in 0..2 {
            if backlash > 0.0 {
                self.xb[i] = self.xb[i].clamp(s.xa[i] - 0.5 * backlash, s.xa[i] + 0.5 * backlash);
            }
            self.t_eng[i] = if out.beta[i] { self.t_eng[i] + h } else { 0.0 };
        }
        for (k, j5) in [0usize, 1, 4].into_iter().enumerate() {
            seen[k].push_back(s.th[j5]);
            let x = seen[k].pop_front().unwrap_or(s.th[j5]);
            self.tc[k][0] = tc_lags[0].step(self.tc[k][0], x);
            self.tc[k][1] = tc_lags[1].step(self.tc[k][1], self.tc[k][0]);
        }
    }
}

/// The torque channel at the `n` samples from the torques of every integration step `t_ms`
/// (`sub` steps of `h` per sample): the sensor's filter, its skew (linear interpolation between
/// steps), then its reading error.
fn torque_channel(
    fx: &Fx,
    t_ms: &mut [Vec<f64>; 2],
    n: usize,
    sub: usize,
    h: f64,
) -> [Vec<f64>; 2] {
    let steps = (n - 1) * sub;
    let s_torque = fx.s_torque;
    let skew_steps = fx.skew / h;
    let tau_f = fx.torque_filter;
    if tau_f > 0.0 {
        for v in t_ms.iter_mut() {
            let (mut y, lag) = (v[0], Lag::new(h, tau_f));
            for x in v.iter_mut() {
                y = lag.step(y, *x);
                *x = y;
            }
        }
    }
    std::array::from_fn(|i| {
        let v = &t_ms[i];
        (0..n)
            .map(|k| {
                let pos = ((k * sub) as f64 - skew_steps).clamp(0.0, steps as f64);
                let a = pos.floor() as usize;
                let f = pos - a as f64;
                let tq = if a < steps {
                    v[a] * (1.0 - f) + v[a + 1] * f
                } else {
                    v[a]
                };
                s_torque.read(tq)
            })
            .collect()
    })
}

/// The thermocouples' reading error `s_temp`, applied to the recorded plate temperatures.
fn thermocouple_reading(s_temp: ReadingError, sig: &mut Signals) {
    if s_temp.is_active() {
        let [pp1, pp2] = &mut sig.pp;
        for v in [pp1, pp2, &mut sig.cd] {
            for x in v.iter_mut() {
                *x = s_temp.read(*x);
            }
        }
    }
}

/// The speed sensors' gain error and skew, applied to the recorded speeds: the input speed read
/// from the dyno's exact speed `skew` earlier, times 1 + the gain error; the braked clutch and
/// output speeds (zero) read as zero.
fn speed_channels(fx: &Fx, rec: &RecordDef, sig: &mut Signals) {
    if fx.speed_gain_error == 0.0 && fx.speed_skew == 0.0 {
        return;
    }
    let g = 1.0 + fx.speed_gain_error;
    for (w, t) in sig.wf.iter_mut().zip(&sig.time) {
        *w = g * rec.speed_radps((t - fx.speed_skew).max(0.0));
    }
}

/// Adds sensor noise and quantisation.
pub fn measure(sig: &Signals, noise: &Noise, rng: &mut Xoshiro) -> Signals {
    let q = |v: f64, step: f64| {
        if step > 0.0 {
            (v / step).round() * step
        } else {
            v
        }
    };
    let mut out = sig.clone();
    let w_sigma = noise.speed_rpm * std::f64::consts::PI / 30.0;
    for k in 0..sig.len() {
        for i in 0..2 {
            out.x[i][k] = q(sig.x[i][k] + noise.pos_mm * rng.normal(), noise.q_pos_mm);
            out.torque[i][k] = q(
                sig.torque[i][k] + noise.torque_nm * rng.normal(),
                noise.q_torque_nm,
            );
            out.pp[i][k] = q(sig.pp[i][k] + noise.temp_c * rng.normal(), noise.q_temp_c);
            out.wc[i][k] = sig.wc[i][k] + w_sigma * rng.normal();
            out.xreq[i][k] = q(sig.xreq[i][k], noise.q_pos_mm);
        }
        out.cd[k] = q(sig.cd[k] + noise.temp_c * rng.normal(), noise.q_temp_c);
        out.th[k] = q(sig.th[k] + noise.temp_c * rng.normal(), noise.q_temp_c);
        out.wf[k] = sig.wf[k] + w_sigma * rng.normal();
        out.wout[k] = sig.wout[k] + w_sigma * rng.normal();
    }
    out
}

/// CSV text in the documented columns (`docs/gap.md`, "Input"); `only_req1` drops
/// `x_to2_req_mm`; `precise` writes 6 decimals everywhere (for unquantised records), else the
/// decimals of the quantisation.
pub fn to_csv(sig: &Signals, only_req1: bool, precise: bool) -> String {
    use std::fmt::Write as _;
    let mut s = String::with_capacity(sig.len() * 128);
    s.push_str("time_s,x_to1_mm,x_to2_mm,w_f_radps,w_c1_radps,w_c2_radps,w_out_radps,T_c1_Nm,T_c2_Nm,th_pp1_C,th_pp2_C,th_cd_C,th_h_C,x_to1_req_mm");
    if !only_req1 {
        s.push_str(",x_to2_req_mm");
    }
    s.push('\n');
    let (dx, dw, dt, dth) = if precise { (6, 6, 6, 6) } else { (3, 4, 1, 1) };
    for k in 0..sig.len() {
        let _ = write!(
            s,
            "{:.2},{:.dx$},{:.dx$},{:.dw$},{:.dw$},{:.dw$},{:.dw$},{:.dt$},{:.dt$},{:.dth$},{:.dth$},{:.dth$},{:.dth$},{:.dx$}",
            sig.time[k],
            sig.x[0][k],
            sig.x[1][k],
            sig.wf[k],
            sig.wc[0][k],
            sig.wc[1][k],
            sig.wout[k],
            sig.torque[0][k],
            sig.torque[1][k],
            sig.pp[0][k],
            sig.pp[1][k],
            sig.cd[k],
            sig.th[k],
            sig.xreq[0][k],
        );
        if !only_req1 {
            let _ = write!(s, ",{:.dx$}", sig.xreq[1][k]);
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Params;
    use crate::truth::experiments;
    use crate::truth::form::{Family, Form};

    fn effect(c: ClassId, magnitude: f64) -> Effect {
        Effect {
            target: Target::Class(c),
            form: Form::Scalar,
            magnitude,
            unit: "",
            anchor_top: false,
            aux: vec![],
        }
    }

    /// Energy: the friction work ∫(T1 + T2)·ω dt equals the heat stored in the pack plus the heat
    /// lost to the housing air (the shares of the friction power add up to one, conduction only
    /// moves heat between the masses).
    #[test]
    fn friction_work_is_stored_or_lost() {
        let ph = Physics::new(&Params::default());
        for rec in [experiments::train_sweep(), experiments::validate_hot()] {
            let s = simulate(&ph, &[], &rec, [0.0; 2], 1);
            let (a, b) = (s.true_temps[0], *s.true_temps.last().unwrap());
            let cap = [ph.c_pp, ph.c_pp, ph.c_c, ph.c_c, ph.c_cd];
            let stored: f64 = (0..5).map(|j| cap[j] * (b[j] - a[j])).sum();
            let balance = stored + s.heat_lost_j;
            let rel = (s.friction_work_j - balance).abs() / s.friction_work_j;
            assert!(
                rel < 1e-3,
                "{}: work {} vs stored+lost {balance} ({rel:e})",
                rec.name,
                s.friction_work_j
            );
            assert!((s.e_end[0] + s.e_end[1] - s.friction_work_j).abs() / s.friction_work_j < 1e-3);
            // The sampled record tells the same: ∫T·ω over the 10 ms samples.
            let g = &s.signals;
            let p: Vec<f64> = (0..g.len())
                .map(|k| (g.torque[0][k] + g.torque[1][k]) * (g.wf[k] - g.wc[0][k]))
                .collect();
            let sampled: f64 = p.windows(2).map(|w| 0.5 * (w[0] + w[1]) * SAMPLE_S).sum();
            let rel = (sampled - s.friction_work_j).abs() / s.friction_work_j;
            assert!(rel < 5e-3, "{}: sampled work off by {rel:e}", rec.name);
        }
    }

    /// The central disk's conduction with the other sign: the balance still closes once the
    /// heat the flipped share creates or destroys is counted, and the central disk — which
    /// gets its own share of the friction power and normally gives heat back to the cooler
    /// clutch disks — keeps it and ends far hotter.
    #[test]
    fn flipped_conduction_heats_the_central_disk_and_is_counted_in_the_balance() {
        let ph = Physics::new(&Params::default());
        let rec = experiments::train_sweep();
        let a = simulate(&ph, &[], &rec, [0.0; 2], 1);
        let e = Effect {
            target: Target::Outside(OutsideKind::ConductionSign),
            form: Form::Scalar,
            magnitude: 1.0,
            unit: "1",
            anchor_top: false,
            aux: vec![],
        };
        let b = simulate(&ph, std::slice::from_ref(&e), &rec, [0.0; 2], 1);
        let (b0, b1) = (b.true_temps[0], *b.true_temps.last().unwrap());
        let cap = [ph.c_pp, ph.c_pp, ph.c_c, ph.c_c, ph.c_cd];
        let stored: f64 = (0..5).map(|j| cap[j] * (b1[j] - b0[j])).sum();
        let rel = (b.friction_work_j - stored - b.heat_lost_j).abs() / b.friction_work_j;
        assert!(rel < 1e-3, "balance off by {rel:e}");
        let (cd_a, cd_b) = (a.true_temps.last().unwrap()[4], b1[4]);
        assert!(
            cd_b > cd_a + 50.0,
            "central disk {cd_b} vs {cd_a} without the flip"
        );
    }

    #[test]
    fn first_order_lag_step_response() {
        let tau = 3.0;
        let mut y = 0.0;
        for k in 1..=10_000 {
            y = lag_step(y, 1.0, STEP_S, tau);
            let t = k as f64 * STEP_S;
            if k % 1000 == 0 {
                assert!((y - (1.0 - (-t / tau).exp())).abs() < 1e-12, "t={t}");
            }
        }
        // In the rig: a lagging thermocouple reads above a cooling central disk and settles on
        // it to within the lag's offset (rate × τ).
        let ph = Physics::new(&Params::default());
        let rec = experiments::validate_hot();
        let e = effect(ClassId::SensorTemperatureLag, 5.0);
        let s = simulate(&ph, std::slice::from_ref(&e), &rec, [0.0; 2], 1);
        let n = s.signals.len();
        let k = n - 10;
        let truth = s.true_temps[k][4];
        let rate = (s.true_temps[k + 1][4] - s.true_temps[k - 1][4]) / (2.0 * SAMPLE_S);
        let expected = truth - rate * 5.0;
        assert!(s.signals.cd[k] > truth);
        assert!((s.signals.cd[k] - expected).abs() < 0.05 * (rate * 5.0).abs() + 1e-3);
    }

    /// A dead time shifts the position response by the dead time (a multiple of the cycle).
    #[test]
    fn dead_time_shifts_the_position() {
        let ph = Physics::new(&Params::default());
        let rec = experiments::validate_mixed();
        let a = simulate(&ph, &[], &rec, [0.0; 2], 1).signals;
        let b = simulate(
            &ph,
            &[effect(ClassId::ActuatorDeadTime, 0.03)],
            &rec,
            [0.0; 2],
            1,
        )
        .signals;
        let worst = (3..a.len())
            .map(|k| (b.x[0][k] - a.x[0][k - 3]).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.02, "{worst}");
        assert_eq!(a.xreq, b.xreq, "the logged request is the command");
    }

    /// Sensor classes change readings only: the physics (true temperatures) is untouched.
    #[test]
    fn sensors_do_not_touch_the_physics() {
        let ph = Physics::new(&Params::default());
        let rec = experiments::train_hot();
        let a = simulate(&ph, &[], &rec, [0.0; 2], 1);
        for (c, m) in [
            (ClassId::SensorTorque, 3.0),
            (ClassId::SensorTemperature, 2.0),
            (ClassId::SensorPosition, 0.1),
            (ClassId::SensorSpeed, 0.03),
        ] {
            let mut e = effect(c, m);
            e.aux = vec![("gain_share", 0.5), ("offset_sign", 1.0)];
            let b = simulate(&ph, &[e], &rec, [0.0; 2], 1);
            assert_eq!(a.true_temps, b.true_temps, "{c}");
            assert_ne!(a.signals, b.signals, "{c}");
        }
    }

    /// The speed sensors read the dyno's speed times 1 + the gain error, `skew_s` late; the
    /// torque, temperatures and positions are what they were.
    #[test]
    fn a_speed_sensor_scales_and_delays_the_speed_channel_only() {
        let ph = Physics::new(&Params::default());
        let rec = experiments::train_hot();
        let a = simulate(&ph, &[], &rec, [0.0; 2], 1).signals;
        let mut e = effect(ClassId::SensorSpeed, 0.03);
        e.aux = vec![("skew_s", 0.02)];
        let b = simulate(&ph, &[e], &rec, [0.0; 2], 1).signals;
        let mut moving = 0;
        for k in 2..a.len() {
            assert!((b.wf[k] - 1.03 * a.wf[k - 2]).abs() < 1e-9, "sample {k}");
            moving += usize::from(a.wf[k] != a.wf[k - 2]);
        }
        assert!(
            moving > 0,
            "the dyno speed never changes: the skew is not checked"
        );
        assert_eq!((a.torque, a.pp, a.cd, a.x), (b.torque, b.pp, b.cd, b.x));
    }

    #[test]
    fn a_multiplier_changes_the_torque_by_its_form() {
        let ph = Physics::new(&Params::default());
        let rec = experiments::train_sweep();
        let a = simulate(&ph, &[], &rec, [0.0; 2], 1).signals;
        let e = Effect {
            target: Target::Class(ClassId::FrictionSlip),
            form: Form::draw(Family::Power, &mut crate::truth::rng::Xoshiro::new(1)),
            magnitude: 0.1,
            unit: "1",
            anchor_top: false,
            aux: vec![],
        };
        let m = 1.0 + e.term(crate::truth::inject::z_slip(rec.speed_radps(5.0)));
        let b = simulate(&ph, std::slice::from_ref(&e), &rec, [0.0; 2], 1).signals;
        // Early in the record (before the extra heat changes the temperatures much) the torque
        // ratio is the multiplier at the dyno speed.
        let k = (0..a.len())
            .find(|&k| {
                a.torque[0][k] > 30.0
                    && a.time[k] < 8.0
                    && (rec.speed_radps(a.time[k]) - rec.speed_radps(5.0)).abs() < 1e-9
            })
            .expect("an engagement at the first speed");
        assert!(
            (b.torque[0][k] / a.torque[0][k] - m).abs() < 2e-3,
            "{} vs {m}",
            b.torque[0][k] / a.torque[0][k]
        );
    }
}

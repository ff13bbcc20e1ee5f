//! Fitted class terms (issue 17 item 1) as they act on the model evaluated on measured data:
//! multipliers on the friction coefficient of (4)–(6) and on the spring load (10), shifts of the
//! kiss point (9), a gain/offset between the measured actuator position and the bearing, and the
//! sensor terms (gain/offset, lag, time skew) between the modelled quantity and its measurement.
//! The library's parametric members (support conduction, backlash, dead time, the hidden
//! surface temperature, facing asymmetry, engine map error) stay in the model's
//! [`EffectSet`](crate::model::effects::EffectSet) and act through `model::effects`.

use crate::gap::model::class::Variable;
use crate::gap::model::shape::{Shape, Site, KNOTS};
use crate::model::clutch;
use crate::model::effects::{self, EffectSet, TorqueContext};
use crate::model::params::{ClutchParams, ThermalParams5};
use crate::model::thermal::{Thermal5State, ThermalInputs};

/// Reference position of the position gain terms (mm): the middle of the engagement range, so
/// that a gain and an offset are nearly independent.
pub const X_REF_MM: f64 = 5.0;
/// Reference temperature of the thermocouple gain (°C).
pub const THETA_REF_C: f64 = 25.0;

/// A gain and offset, `measured = value + offset + (gain − 1)·(value − reference)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GainOffset {
    pub gain: f64,
    pub offset: f64,
}

impl GainOffset {
    #[inline]
    pub fn apply(&self, v: f64, reference: f64) -> f64 {
        v + self.offset + (self.gain - 1.0) * (v - reference)
    }

    /// The value that `apply` maps to `measured`.
    #[inline]
    pub fn invert(&self, measured: f64, reference: f64) -> f64 {
        (measured - self.offset + (self.gain - 1.0) * reference) / self.gain.max(1e-6)
    }
}

/// A thermocouple's reading error, `measured = θ + offset + s(θ)`: an offset and a curve in the
/// temperature itself (zero at its first knot, the training records' 2 % quantile of the
/// readings). A gain is the straight special case; a bent characteristic (a reading error that
/// grows with the square of the temperature, a kink) is within the knots' interpolation error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    pub offset: f64,
    pub shape: Shape,
}

impl Reading {
    #[inline]
    pub fn apply(&self, v: f64) -> f64 {
        v + self.offset + self.shape.eval(v)
    }

    /// The temperature that `apply` maps to `measured` (see [`ReadingInverse`]).
    pub fn invert(&self, measured: f64) -> f64 {
        self.inverse().eval(measured)
    }

    /// The inverse map, prepared once for a series of readings.
    pub fn inverse(&self) -> ReadingInverse {
        let z = self.shape.z;
        let y = z.map(|v| self.apply(v));
        let slope: [f64; KNOTS - 1] =
            std::array::from_fn(|i| (y[i + 1] - y[i]) / (z[i + 1] - z[i]).max(1e-300));
        ReadingInverse {
            reading: *self,
            y,
            slope,
            monotone: slope.iter().all(|s| *s >= 0.1),
        }
    }
}

/// The inverse of a thermocouple reading `apply` (piecewise linear, so its inverse is too):
/// exact on the segment whose image holds the reading; a reading that falls with the
/// temperature (a segment slope below 0.1) is not a thermocouple and is inverted by Newton with
/// the slope held ≥ 0.1.
#[derive(Debug, Clone, Copy)]
pub struct ReadingInverse {
    reading: Reading,
    /// Images of the knots.
    y: [f64; KNOTS],
    /// Slope of the map on each segment (the end ones extrapolated).
    slope: [f64; KNOTS - 1],
    monotone: bool,
}

impl ReadingInverse {
    #[inline]
    pub fn eval(&self, measured: f64) -> f64 {
        if self.monotone {
            let mut seg = 0;
            while seg < KNOTS - 2 && measured > self.y[seg + 1] {
                seg += 1;
            }
            return self.reading.shape.z[seg] + (measured - self.y[seg]) / self.slope[seg];
        }
        let (r, s) = (&self.reading, &self.reading.shape);
        let mut v = measured - r.offset - s.eval(measured);
        for _ in 0..6 {
            let e = r.apply(v) - measured;
            if e.abs() < 1e-9 {
                break;
            }
            v -= e / (1.0 + s.slope(v)).max(0.1);
        }
        v
    }
}

impl Reading {
    /// Largest |reading error| over `[lo, hi]` (at the ends and the knots inside).
    pub fn largest_error(&self, lo: f64, hi: f64) -> f64 {
        self.largest_signed_error(lo, hi).abs()
    }

    /// The reading error of largest size over `[lo, hi]`, with its sign.
    pub fn largest_signed_error(&self, lo: f64, hi: f64) -> f64 {
        let inside = self.shape.z.iter().copied().filter(|z| *z > lo && *z < hi);
        largest_signed(inside.chain([lo, hi]).map(|v| self.apply(v) - v))
    }
}

/// The value of largest size, with its sign (0 for none).
pub fn largest_signed(values: impl Iterator<Item = f64>) -> f64 {
    values.fold(0.0, |a: f64, b: f64| if b.abs() > a.abs() { b } else { a })
}

/// Heat flow to supports at the housing temperature (K/s): s(θ − θ_h) from each clutch disk,
/// weighted for the pressure plates and the central disk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Support {
    pub shape: Shape,
    pub w_pp: f64,
    pub w_cd: f64,
}

impl Support {
    /// Temperature rates (K/s) the supports take from each body.
    #[inline]
    pub fn loss(&self, s: &Thermal5State, theta_h: f64) -> Thermal5State {
        let q = |t: f64| self.shape.eval(t - theta_h).max(0.0);
        Thermal5State {
            pp1: -self.w_pp * q(s.pp1),
            pp2: -self.w_pp * q(s.pp2),
            c1: -q(s.c1),
            c2: -q(s.c2),
            cd: -self.w_cd * q(s.cd),
        }
    }
}

/// Convection of (16) scaled by 1 + s(ω_f) with the flywheel speed (the plates and the central
/// disk turn with the flywheel; the model's α2, α6, α8 are constant).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Convection {
    pub shape: Shape,
}

impl Convection {
    /// Extra temperature rates (K/s): s(ω_f) times the model's convective rates.
    #[inline]
    pub fn rates(&self, a: &ThermalParams5, s: &Thermal5State, u: &ThermalInputs) -> Thermal5State {
        // Convection cannot turn into heating: the factor 1 + s stays ≥ 0.
        let k = self.shape.eval(u.w_f_radps.abs()).max(-1.0);
        let (o1, o2) = (1.0 - u.beta1, 1.0 - u.beta2);
        let th = u.theta_h_c;
        Thermal5State {
            pp1: k * a.alpha2_per_s * o1 * (th - s.pp1),
            pp2: k * a.alpha2_per_s * o2 * (th - s.pp2),
            c1: k * a.alpha6_per_s * o1 * (th - s.c1),
            c2: k * a.alpha6_per_s * o2 * (th - s.c2),
            cd: k * a.alpha8_per_s * (o1 + o2) * (th - s.cd),
        }
    }
}

/// A share s(P) of the friction heat the model gives the pressure plate (α3·P of (16a)) goes to
/// the clutch disk instead, depending on the friction power P; `w_c` converts the plate's rate
/// into the disk's (the ratio of their heat capacities, fitted).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Partition {
    pub shape: Shape,
    pub w_c: f64,
}

impl Partition {
    /// Extra temperature rates (K/s).
    #[inline]
    pub fn rates(&self, a: &ThermalParams5, u: &ThermalInputs) -> Thermal5State {
        let moved = |p: f64| {
            let p = p.max(0.0);
            a.alpha3_k_per_j * self.shape.eval(p) * p
        };
        let (m1, m2) = (moved(u.p_fric1_w), moved(u.p_fric2_w));
        Thermal5State {
            pp1: -m1,
            pp2: -m2,
            c1: self.w_c * m1,
            c2: self.w_c * m2,
            cd: 0.0,
        }
    }
}

/// The hidden facing-surface (flash) temperature in its flexible form: θ̇_s = (θ_c + rise(P) −
/// θ_s)/τ_s per clutch, the steady rise a non-decreasing curve in the friction power P anchored
/// at zero power (the library member's rise h·P·τ_s is its straight special case; a rise that
/// saturates, or grows as a power of P, is within the knots' interpolation error).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Surface {
    /// Steady rise above θ_c (K) over the friction power (W).
    pub rise: Shape,
    /// Relaxation time (s).
    pub tau_s: f64,
}

impl Surface {
    /// The surface temperature one step `dt` later, exact for inputs held over the step
    /// (`decay` = e^(−dt/τ_s)).
    #[inline]
    pub fn step(&self, theta_s: f64, theta_c: f64, p_fric_w: f64, decay: f64) -> f64 {
        self.step_at(theta_s, theta_c, self.rise.locate(p_fric_w.max(0.0)), decay)
    }

    /// [`Self::step`] with the friction power (floored at zero) already located on the rise's
    /// knots.
    #[inline]
    pub fn step_at(&self, theta_s: f64, theta_c: f64, power: Site, decay: f64) -> f64 {
        let target = theta_c + self.rise.at(power).max(0.0);
        target + (theta_s - target) * decay
    }

    /// The library member's parameters (h, τ_s) nearest this term: h·τ_s the least-squares
    /// slope through the origin of the rise over the knots.
    pub fn member(&self) -> [f64; 2] {
        let (sxy, sxx) = self
            .rise
            .z
            .iter()
            .zip(&self.rise.v)
            .fold((0.0, 0.0), |(a, b), (z, v)| (a + z * v, b + z * z));
        let tau = self.tau_s.max(1e-3);
        [if sxx > 0.0 { sxy / sxx / tau } else { 0.0 }, tau]
    }
}

/// The thermal class terms with the thermal parameters they scale: what the thermal replays add
/// to (16) besides the library's effects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThermalTerms {
    pub a: ThermalParams5,
    pub support: Option<Support>,
    pub convection: Option<Convection>,
    pub partition: Option<Partition>,
}

impl ThermalTerms {
    /// Extra temperature rates (K/s) of every thermal term.
    #[inline]
    pub fn rates(&self, s: &Thermal5State, u: &ThermalInputs) -> Thermal5State {
        let mut r = Thermal5State::default();
        if let Some(sp) = &self.support {
            r = r.axpy(1.0, &sp.loss(s, u.theta_h_c));
        }
        if let Some(c) = &self.convection {
            r = r.axpy(1.0, &c.rates(&self.a, s, u));
        }
        if let Some(p) = &self.partition {
            r = r.axpy(1.0, &p.rates(&self.a, u));
        }
        r
    }
}

/// The speed channels (input shaft or dyno, clutches, engine) as the speed sensors read them:
/// measured ω(t) = gain·ω(t − skew_s). They set the slip the friction model sees — its slip
/// dependence Q(ω) of (6) and the friction power T·ω_fc that heats (16).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedSensor {
    /// Measured over true speed (1: exact).
    pub gain: f64,
    /// The speed channels are recorded `skew_s` late (s; negative: early).
    pub skew_s: f64,
}

impl SpeedSensor {
    /// The true speed of a measured series sampled every `dt` s: read `skew_s` ahead
    /// (interpolated, held at the ends), divided by the gain.
    pub fn true_speeds<C: FromIterator<f64>>(&self, measured: &[f64], dt: f64) -> C {
        let shift = self.skew_s / dt;
        let last = measured.len().saturating_sub(1);
        (0..measured.len())
            .map(|k| {
                // Clamped to ≥ 0, so the truncation is the floor.
                let pos = (k as f64 + shift).clamp(0.0, last as f64);
                let a = pos as usize;
                let f = pos - a as f64;
                let v = if a < last {
                    measured[a] * (1.0 - f) + measured[a + 1] * f
                } else {
                    measured[a]
                };
                v / self.gain
            })
            .collect()
    }
}

/// The class terms of a model (all off by default).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Terms {
    /// Friction multipliers 1 + s(z) on the torque, each in its own variable.
    pub mu: [Option<(Variable, Shape)>; 2],
    /// Static friction μ_s × (1 + s(θ_c)).
    pub mu_static: Option<Shape>,
    /// Spring load × (1 + s(θ_c)).
    pub spring: Option<Shape>,
    /// Kiss point + s(z) (mm); with the friction energy the whole characteristic moves (x_to,max
    /// too), with the temperature the kiss point alone.
    pub kiss: Option<(Variable, Shape)>,
    /// Bearing = transfer(measured actuator position).
    pub transfer: Option<GainOffset>,
    /// Measured torque = torque_sensor(torque).
    pub torque_sensor: Option<GainOffset>,
    /// The torque channel is recorded `torque_skew_s` late (s; negative: early).
    pub torque_skew_s: f64,
    /// Thermocouple lag (s): the sum of two first-order lags in series (a junction and its
    /// sheath or contact), the second taking `temp_lag2_share` of it (0: a single lag).
    pub temp_lag_s: f64,
    /// Share of `temp_lag_s` in the second lag (0…0.5: the two lags commute).
    pub temp_lag2_share: f64,
    /// Measured temperature = temp_sensor(temperature).
    pub temp_sensor: Option<Reading>,
    /// Measured position = pos_sensor(position).
    pub pos_sensor: Option<GainOffset>,
    /// The speed channels' gain and time skew.
    pub speed_sensor: Option<SpeedSensor>,
    /// Conduction to supports.
    pub support: Option<Support>,
    /// Convection depending on the flywheel speed.
    pub convection: Option<Convection>,
    /// Heat partition between plate and disk depending on the friction power.
    pub partition: Option<Partition>,
    /// Hidden facing-surface temperature (flexible form of the library member).
    pub surface: Option<Surface>,
}

/// Measured variables at one torque sample besides the clutch context.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Extra {
    /// Sliding acceleration d|ω_fc|/dt (rad/s²).
    pub slide_acc: f64,
}

impl Terms {
    pub fn is_nominal(&self) -> bool {
        *self == Terms::default()
    }

    /// True when a term changes the torque at given measured inputs.
    pub fn touches_torque(&self) -> bool {
        self.mu.iter().any(Option::is_some)
            || self.mu_static.is_some()
            || self.spring.is_some()
            || self.kiss.is_some()
            || self.transfer.is_some()
            || self.torque_sensor.is_some()
            || self.torque_skew_s != 0.0
            || self.pos_sensor.is_some()
            || self.speed_sensor.is_some()
    }

    /// The bearing position for a measured actuator position (sensor and transfer terms).
    #[inline]
    pub fn bearing(&self, x_measured: f64) -> f64 {
        let x = match &self.pos_sensor {
            Some(g) => g.invert(x_measured, X_REF_MM),
            None => x_measured,
        };
        match &self.transfer {
            Some(g) => g.apply(x, X_REF_MM),
            None => x,
        }
    }

    /// Clutch torque (13) with the library effects of `set` and these terms, at a context whose
    /// `x_to_mm` is already the bearing position. Not the sensor terms (see
    /// [`Terms::measured_torque`]).
    #[inline]
    pub fn torque(&self, p: &ClutchParams, set: &EffectSet, c: &TorqueContext, x: &Extra) -> f64 {
        let needs_local = self.kiss.is_some() || self.mu_static.is_some();
        let local;
        let pc = if needs_local {
            let mut q = *p;
            if let Some((var, s)) = &self.kiss {
                let d = s.eval(self.var(*var, p, c, x));
                q.x_isp0_mm += d;
                if *var == Variable::FrictionEnergy {
                    q.x_to_max_mm += d;
                }
            }
            if let Some(s) = &self.mu_static {
                q.mu_s *= (1.0 + s.eval(c.theta_c)).max(0.05);
            }
            local = q;
            &local
        } else {
            p
        };
        let t = effects::torque(pc, set, c);
        if t == 0.0 {
            return 0.0;
        }
        let mut f = 1.0;
        if let Some(s) = &self.spring {
            f *= (1.0 + s.eval(c.theta_c)).max(0.05);
        }
        for (var, s) in self.mu.iter().flatten() {
            f *= (1.0 + s.eval(self.var(*var, pc, c, x))).max(0.05);
        }
        t * f
    }

    /// The torque as the sensor reports it.
    #[inline]
    pub fn measured_torque(&self, t: f64) -> f64 {
        match &self.torque_sensor {
            Some(g) => g.apply(t, 0.0),
            None => t,
        }
    }

    /// Value of a class variable at a torque sample.
    #[inline]
    fn var(&self, v: Variable, p: &ClutchParams, c: &TorqueContext, x: &Extra) -> f64 {
        variable(v, p, c, x)
    }
}

/// Value of a class variable at a torque sample (clamp load with the parameters `p`).
#[inline]
pub fn variable(v: Variable, p: &ClutchParams, c: &TorqueContext, x: &Extra) -> f64 {
    match v {
        Variable::Temperature => c.theta_c,
        Variable::Slip => c.slip_radps.abs(),
        Variable::ClampLoad => clutch::normal_force(p, c.x_to_mm, c.theta_c),
        Variable::SlidingAcceleration => x.slide_acc,
        Variable::FrictionEnergy => c.e_fric_j * 1e-6,
        _ => 0.0,
    }
}

/// First-order lag τ·ẏ = x − y of a sampled series (time constant `tau_s`, step `dt`), starting
/// at the first sample: the exact solution for an input linear between samples (first-order
/// hold), so that the lag of a series sampled every 10 ms and of the same series every 0.3 s
/// agree wherever the input is linear in between — the thermal replay steps by the temperature
/// samples' stride.
pub fn lag(v: &[f64], tau_s: f64, dt: f64) -> Vec<f64> {
    if tau_s <= 0.0 || v.is_empty() {
        return v.to_vec();
    }
    let e = (-dt / tau_s).exp();
    let mut y = v[0];
    let mut out = Vec::with_capacity(v.len());
    out.push(y);
    for w in v.windows(2) {
        // x(t) = x0 + s·t: y(dt) = x1 − s·τ + (y0 − x0 + s·τ)·e^{−dt/τ}.
        let s_tau = (w[1] - w[0]) / dt * tau_s;
        y = w[1] - s_tau + (y - w[0] + s_tau) * e;
        out.push(y);
    }
    out
}

/// Two first-order lags in series, `tau_s` in all, the second taking `share2` of it (0: one
/// lag): a thermocouple junction behind its sheath or contact. The second stage takes the
/// first's output as linear between samples (it is not quite): an error of order h²·ẍ,
/// negligible for a step h far below the lags (the replay's 0.3 s against lags of seconds).
pub fn lag2(v: &[f64], tau_s: f64, share2: f64, dt: f64) -> Vec<f64> {
    let share2 = share2.clamp(0.0, 1.0);
    lag(&lag(v, tau_s * (1.0 - share2), dt), tau_s * share2, dt)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::effects::EffectId;
    use crate::model::params::Params;

    /// A straight rise h·P·τ_s is the library member: the same exact step as
    /// `effects::surface_temperature_step` (powers beyond the last knot and negative ones
    /// included), and [`Surface::member`] gives h and τ_s back.
    #[test]
    fn a_straight_surface_rise_is_the_library_member() {
        let (h, tau) = (8e-3, 0.4);
        let z = [0.0, 2e3, 5e3, 1e4, 2e4, 3e4, 4.5e4];
        let s = Surface {
            rise: Shape {
                z,
                v: z.map(|p| h * p * tau),
            },
            tau_s: tau,
        };
        let set = EffectSet::single(EffectId::SurfaceTemperatureFriction, &[h, tau]).unwrap();
        let dt = 0.01;
        let (mut a, mut b) = (60.0, 60.0);
        for k in 0..500 {
            let p = match k % 97 {
                0 => 6e4,
                1 => -2e3,
                _ => 25e3 * (k as f64 * 0.05).sin().abs(),
            };
            let theta_c = 60.0 + 0.02 * k as f64;
            a = s.step(a, theta_c, p, (-dt / tau).exp());
            b = effects::surface_temperature_step(&set, b, theta_c, p, dt);
            assert!((a - b).abs() < 1e-9, "{k}: {a} vs {b}");
        }
        let m = s.member();
        assert!(
            (m[0] - h).abs() < 1e-12 && (m[1] - tau).abs() < 1e-12,
            "{m:?}"
        );
    }

    /// The straight curve is a gain and an offset (the gain's reference at the first knot); a
    /// bent one inverts exactly too, and its largest error is found at a knot inside the range.
    #[test]
    fn a_thermocouple_reading_is_a_gain_offset_or_a_bend_and_inverts() {
        let z = [30.0, 55.0, 80.0, 120.0, 170.0, 205.0, 240.0];
        let straight = Reading {
            offset: 1.5,
            shape: Shape {
                z,
                v: z.map(|t| 0.03 * (t - 30.0)),
            },
        };
        let g = GainOffset {
            gain: 1.03,
            offset: 1.5,
        };
        for v in [10.0, 30.0, 95.0, 240.0, 300.0] {
            assert!((straight.apply(v) - g.apply(v, 30.0)).abs() < 1e-9, "{v}");
        }
        let bent = Reading {
            offset: -0.5,
            shape: Shape {
                z,
                v: [0.0, -0.1, -0.2, -3.0, -3.5, -3.8, -4.0],
            },
        };
        for v in [0.0, 25.0, 100.0, 119.0, 121.0, 200.0, 280.0] {
            assert!((bent.invert(bent.apply(v)) - v).abs() < 1e-9, "{v}");
        }
        // The largest |error| over 20…150 °C equals the maximum over a fine grid (piecewise
        // linear: it sits at an end or a knot).
        let grid = (0..=1300)
            .map(|i| 20.0 + 0.1 * f64::from(i))
            .map(|v| (bent.apply(v) - v).abs())
            .fold(0.0, f64::max);
        assert!((bent.largest_error(20.0, 150.0) - grid).abs() < 1e-9);
        assert!((grid - 3.8).abs() < 1e-9);
    }

    #[test]
    fn gain_offset_inverts() {
        let g = GainOffset {
            gain: 1.04,
            offset: -0.3,
        };
        for v in [0.0, 3.0, 7.5] {
            assert!((g.invert(g.apply(v, X_REF_MM), X_REF_MM) - v).abs() < 1e-12);
        }
    }

    #[test]
    fn nominal_terms_leave_the_torque_unchanged() {
        let p = Params::default();
        let c = TorqueContext::new(5.5, 150.0, 120.0);
        let t0 = effects::torque(&p.clutch, &EffectSet::nominal(), &c);
        let t = Terms::default().torque(&p.clutch, &EffectSet::nominal(), &c, &Extra::default());
        assert_eq!(t, t0);
    }

    #[test]
    fn a_spring_term_scales_the_torque() {
        let p = Params::default();
        let c = TorqueContext::new(5.5, 150.0, 120.0);
        let t0 = clutch::torque(&p.clutch, 5.5, 150.0, 120.0);
        let z = std::array::from_fn(|i| 25.0 + 225.0 * i as f64 / (KNOTS - 1) as f64);
        let s = Shape::from_increments(z, &[-0.1]);
        let terms = Terms {
            spring: Some(s),
            ..Terms::default()
        };
        let t = terms.torque(&p.clutch, &EffectSet::nominal(), &c, &Extra::default());
        assert!((t / t0 - (1.0 + s.eval(120.0))).abs() < 1e-12);
    }

    #[test]
    fn lag_step_response_is_exponential() {
        let (tau, h) = (2.0f64, 0.01);
        let mut v = vec![1.0; 1001];
        v[0] = 0.0;
        let y = lag(&v, tau, h);
        // The input rises linearly over the first step, then holds: for t ≥ h,
        // y(t) = 1 − (τ/h)·(e^{h/τ} − 1)·e^{−t/τ}.
        for k in [1, 101, 1000] {
            let t = k as f64 * h;
            let exact = 1.0 - tau / h * ((h / tau).exp() - 1.0) * (-t / tau).exp();
            assert!((y[k] - exact).abs() < 1e-12, "k {k}: {} vs {exact}", y[k]);
        }
    }

    /// The lag of a series and of the same series sampled 30 times less often agree at the
    /// common samples when the input is linear between the coarse samples (the thermal
    /// replay's stride); and a ramp is followed τ behind.
    #[test]
    fn lag_is_the_same_on_a_coarser_grid_and_follows_a_ramp_tau_behind() {
        let (tau, h) = (3.0, 0.01);
        // Piecewise linear with kinks every 0.3 s.
        let coarse: Vec<f64> = (0..200).map(|j| ((j * 7919) % 13) as f64).collect();
        let fine: Vec<f64> = (0..(coarse.len() - 1) * 30 + 1)
            .map(|k| {
                let (j, f) = (k / 30, (k % 30) as f64 / 30.0);
                if f == 0.0 {
                    coarse[j]
                } else {
                    coarse[j] + f * (coarse[j + 1] - coarse[j])
                }
            })
            .collect();
        let (yf, yc) = (lag(&fine, tau, h), lag(&coarse, tau, 30.0 * h));
        for (j, c) in yc.iter().enumerate() {
            assert!(
                (yf[30 * j] - c).abs() < 1e-9,
                "sample {j}: {} vs {c}",
                yf[30 * j]
            );
        }
        let ramp: Vec<f64> = (0..3001).map(|k| k as f64 * h).collect();
        let y = lag(&ramp, tau, h);
        // y(t) = t − τ·(1 − e^{−t/τ}): τ behind once the start has faded.
        assert!((ramp[3000] - y[3000] - tau * (1.0 - (-30.0 / tau).exp())).abs() < 1e-9);
    }

    /// Two lags in series on a ramp x = t, against the analytic response
    /// y = t − (τa + τb) + (τa² e^{−t/τa} − τb² e^{−t/τb}) / (τa − τb); a zero share is the
    /// single lag.
    #[test]
    fn two_lags_in_series_follow_a_ramp_as_the_analytic_solution() {
        let (h, tau, share2) = (0.01, 6.0, 0.35);
        let (ta, tb) = (tau * (1.0 - share2), tau * share2);
        let ramp: Vec<f64> = (0..2001).map(|k| k as f64 * h).collect();
        let y = lag2(&ramp, tau, share2, h);
        for k in [1, 50, 300, 1000, 2000] {
            let t = ramp[k];
            let exact =
                t - (ta + tb) + (ta * ta * (-t / ta).exp() - tb * tb * (-t / tb).exp()) / (ta - tb);
            assert!((y[k] - exact).abs() < 1e-5, "t {t}: {} vs {exact}", y[k]);
        }
        assert_eq!(lag2(&ramp, tau, 0.0, h), lag(&ramp, tau, h));
    }
}

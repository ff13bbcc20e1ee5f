//! The model evaluated on measured data, per subsystem, so that a gap in one subsystem does not
//! smear into the others (DESIGN.md §6 step 2):
//!
//! - torque characteristic (13) in equation-error form: measured x_to and slip, clutch-disk
//!   temperature θ_c from [`disk_estimate`] — the disk equations (16c)/(16d) driven by the
//!   *measured* pressure-plate, central-disk and housing temperatures and the *measured* friction
//!   power T_c·ω_fc (the disk temperature itself is not measured on the bench);
//! - thermal model (16) in replay form: all five temperatures simulated from the measured friction
//!   power and housing temperature ([`thermal_replay`]), compared with the measured θ_pp, θ_cd;
//! - actuator: the bearing position simulated from the position request through the nominal
//!   first-order lag with rate limit ([`actuator_replay`]);
//! - engine: the flywheel balance J_eq·ω̇_f = T_e − T_c1 − T_c2 (18a) with measured torques, as
//!   window means ([`crate::gap::eval::predict`]);
//! - and the free-running replay of the whole rig model ([`full_replay`]): torque and
//!   temperatures simulated from the measured inputs only (x_to, speeds, θ_h), the model's own
//!   torque heating its own thermal state — the "replay error" beside the equation error.
//!
//! Reality effects enter through the powertrain's [`Hooks`], exactly as in the plant.

use crate::gap::record::measured::Measured;
use crate::gap::record::series::window_mean;
use crate::model::actuator;
use crate::model::integrator::rk4_step_with;
use crate::model::params::{ActuatorParams, Params};
use crate::model::powertrain::{ClutchContext, Hooks};
use crate::model::thermal::{Thermal5, Thermal5State, ThermalInputs};

pub use crate::gap::eval::disk::disk_estimate;

/// Equation-error torque of clutch `i` at sample `k` (N·m).
#[inline]
pub fn torque_eq<H: Hooks + ?Sized>(
    p: &Params,
    h: &H,
    m: &Measured,
    theta_c: &[Vec<f64>; 2],
    i: usize,
    k: usize,
) -> f64 {
    h.clutch_torque(&p.clutch, &m.context(i, k, theta_c[i][k]))
}

/// Thermal inputs at an interval midpoint (β filled in at the step's start by [`with_beta`]).
pub(crate) fn inputs(pw: [f64; 2], th: f64, w_f: f64) -> ThermalInputs {
    ThermalInputs {
        p_fric1_w: pw[0],
        p_fric2_w: pw[1],
        theta_h_c: th,
        w_f_radps: w_f,
        ..ThermalInputs::default()
    }
}

/// `u` with β of both clutches at the state `s` of the step's start, held over the step like
/// the other inputs (as [`disk_estimate`] does): β is a step function of x_to and θ_c, and the
/// few mK an RK4 stage moves θ_c would only move where within a 10 ms step it switches.
pub(crate) fn with_beta<H: Hooks + ?Sized>(
    p: &Params,
    h: &H,
    s: &Thermal5State,
    ctx: [ClutchContext; 2],
    u: ThermalInputs,
) -> ThermalInputs {
    let mut c = ctx;
    c[0].theta_c = s.c1;
    c[0].theta_pp = s.pp1;
    c[0].theta_cd = s.cd;
    c[1].theta_c = s.c2;
    c[1].theta_pp = s.pp2;
    c[1].theta_cd = s.cd;
    ThermalInputs {
        beta1: h.clutch_beta(&p.clutch, &c[0]),
        beta2: h.clutch_beta(&p.clutch, &c[1]),
        ..u
    }
}

fn thermal_derivative<H: Hooks + ?Sized>(
    t5: &Thermal5,
    h: &H,
    s: &Thermal5State,
    u: &ThermalInputs,
) -> Thermal5State {
    t5.derivative(s, u).axpy(1.0, &h.extra_heat(s, u))
}

/// The thermal model (16) simulated over the record from the measured friction power and housing
/// temperature (RK4 per sample, inputs held at the interval midpoint), starting from the measured
/// temperatures at the first sample.
pub fn thermal_replay<H: Hooks + ?Sized>(p: &Params, h: &H, m: &Measured) -> Vec<Thermal5State> {
    thermal_replay_every(p, h, m, 1)
}

/// [`thermal_replay`] at every `stride`-th sample only: one RK4 step per `stride` samples with
/// the inputs averaged over the step — the friction power by the energy it delivers (the mean of
/// the per-sample midpoints, so the heat put in is the same as per sample), β as the mean of its
/// per-sample values at the step's starting state. Element `j` is the state at sample
/// `j·stride`; `stride` 1 is the per-sample replay.
///
/// Why this is accurate: (16) is slow — its fastest rate, α4 + α5 ≈ 0.02 /s on a closed clutch,
/// moves the states by 0.6 % of their differences in a 0.3 s step — and the fast part, the
/// heating α3·P, α7·P, α9·P, enters only through the energy, which the averaging keeps exact.
/// A test bounds the difference to the per-sample replay at 0.3 s steps.
pub fn thermal_replay_every<H: Hooks + ?Sized>(
    p: &Params,
    h: &H,
    m: &Measured,
    stride: usize,
) -> Vec<Thermal5State> {
    replay_windows(p, h, m, stride, |k0, k1, s| {
        let len = (k1 - k0) as f64;
        let mean = |v: &[f64]| window_mean(v, k0, k1);
        let pw = [mean(&m.power[0]), mean(&m.power[1])];
        let mut u = inputs(pw, mean(&m.th), mean(&m.w_f));
        let (mut b1, mut b2) = (0.0, 0.0);
        let span = m.span(k0, k1);
        for j in 0..span.len() {
            let ctx = [span.context(0, j, s.c1), span.context(1, j, s.c2)];
            let b = with_beta(p, h, s, ctx, u);
            b1 += b.beta1;
            b2 += b.beta2;
        }
        u.beta1 = b1 / len;
        u.beta2 = b2 / len;
        u
    })
}

/// The stepping of [`thermal_replay_every`]: one RK4 step per `stride` samples from the measured
/// start, the inputs of the step from `k0` to `k1` at the state `s` of its start given by
/// `inputs(k0, k1, s)` (β included). Element `j` is the state at sample `j·stride`.
pub fn replay_windows<H: Hooks + ?Sized>(
    p: &Params,
    h: &H,
    m: &Measured,
    stride: usize,
    mut inputs: impl FnMut(usize, usize, &Thermal5State) -> ThermalInputs,
) -> Vec<Thermal5State> {
    let stride = stride.max(1);
    let t5 = Thermal5::new(p.thermal5);
    let mut s = m.start;
    let mut out = Vec::with_capacity(m.n.div_ceil(stride));
    let mut k0 = 0;
    loop {
        out.push(s);
        if k0 + stride >= m.n {
            break;
        }
        let k1 = k0 + stride;
        let u = inputs(k0, k1, &s);
        let f = |s: &Thermal5State| thermal_derivative(&t5, h, s, &u);
        s = rk4_step_with(&s, (k1 - k0) as f64 * m.dt, f);
        k0 = k1;
    }
    out
}

/// Free-running replay of the rig model from the measured inputs (x_to, slip, θ_h) only.
#[derive(Debug, Clone, PartialEq)]
pub struct Replay {
    pub torque: [Vec<f64>; 2],
    pub thermal: Vec<Thermal5State>,
}

/// Simulates torque (13) and temperatures (16) together: the model's own torque heats its own
/// thermal state (explicit midpoint coupling per sample, RK4 for the temperatures).
pub fn full_replay<H: Hooks + ?Sized>(p: &Params, h: &H, m: &Measured) -> Replay {
    let t5 = Thermal5::new(p.thermal5);
    let mut s = m.start;
    let mut torque = [Vec::with_capacity(m.n), Vec::with_capacity(m.n)];
    let mut thermal = Vec::with_capacity(m.n);
    let mut e = [m.e_cum[0][0], m.e_cum[1][0]];
    for k in 0..m.n {
        let ctx = |i: usize, s: &Thermal5State, e: f64| ClutchContext {
            clutch: i,
            x_to_mm: m.x[i][k],
            slip_radps: m.slip[i][k],
            theta_c: if i == 0 { s.c1 } else { s.c2 },
            theta_pp: if i == 0 { s.pp1 } else { s.pp2 },
            theta_cd: s.cd,
            e_fric_j: e,
        };
        let tq = [0, 1].map(|i| h.clutch_torque(&p.clutch, &ctx(i, &s, e[i])));
        torque[0].push(tq[0]);
        torque[1].push(tq[1]);
        thermal.push(s);
        if k + 1 == m.n {
            break;
        }
        let pw = [0, 1].map(|i| (tq[i] * m.slip[i][k]).max(0.0));
        let mid = |v: &[f64]| 0.5 * (v[k] + v[k + 1]);
        let u = inputs(pw, mid(&m.th), mid(&m.w_f));
        let c = [ctx(0, &s, e[0]), ctx(1, &s, e[1])];
        let u = with_beta(p, h, &s, c, u);
        let f = |s: &Thermal5State| thermal_derivative(&t5, h, s, &u);
        s = rk4_step_with(&s, m.dt, f);
        e[0] += pw[0] * m.dt;
        e[1] += pw[1] * m.dt;
    }
    Replay { torque, thermal }
}

/// The bearing position simulated from its request through the first-order lag with rate limit
/// (RK4 per sample, request held), starting at the measured position. `map` turns the
/// request into the one the lag sees (identity for the nominal actuator; effects such as a dead
/// time or backlash are applied by the caller through it).
pub fn actuator_replay(a: &ActuatorParams, x_req: &[f64], x0: f64, dt: f64) -> Vec<f64> {
    // Ten RK4 substeps per sample: the plant integrates at 1 ms and the rate limit is a kink.
    const SUB: usize = 10;
    let h = dt / SUB as f64;
    let linear = LinearLag::new(a, h, SUB);
    let mut x = x0;
    let mut out = Vec::with_capacity(x_req.len());
    for (k, &r) in x_req.iter().enumerate() {
        out.push(x);
        if k + 1 == x_req.len() {
            break;
        }
        // At rest on its (clamped) request the lag's rate is exactly zero, and so is every
        // RK4 stage: the substeps would leave the position as it is.
        let rc = actuator::clamp_request(a, r, x);
        if rc != x {
            x = match linear.step(x, rc) {
                Some(x) => x,
                None => lag_substeps(a, x, r, h, SUB),
            };
        }
        // Settled: snap to the request (the exponential approach would otherwise run into
        // subnormal numbers, which are two orders of magnitude slower).
        if (x - r).abs() < 1e-9 {
            x = r;
        }
    }
    out
}

/// The `n` RK4 substeps of [`lag_substeps`] in one multiplication while the rate limit is not
/// reached. Below it the lag is linear, ẋ = (r − x)/τ, and one RK4 step of length h multiplies
/// the distance to the held request by the stability polynomial R(z) = 1 + z + z²/2 + z³/6 + z⁴/24,
/// z = −h/τ; n steps by Rⁿ. The distance only shrinks (0 < R < 1 for h < τ), so when the start is
/// within the linear range every stage of every substep is. The product rounds differently from
/// the substeps (a few ulps of the distance, checked in the tests).
#[derive(Debug, Clone, Copy)]
struct LinearLag {
    /// Rⁿ, and the largest distance |r − x| of the linear range (rate·τ) with a margin of 1e-9
    /// against the clamp's rounding; `None` when h ≥ τ (R not in (0, 1): substeps).
    factor: Option<(f64, f64)>,
}

impl LinearLag {
    fn new(a: &ActuatorParams, h: f64, n: usize) -> Self {
        let z = -h / a.tau_s;
        let r = 1.0 + z * (1.0 + z / 2.0 * (1.0 + z / 3.0 * (1.0 + z / 4.0)));
        let valid = h < a.tau_s && r > 0.0 && r < 1.0;
        LinearLag {
            factor: valid.then(|| (r.powi(n as i32), a.rate_mm_per_s * a.tau_s * (1.0 - 1e-9))),
        }
    }

    /// The position after the substeps from `x` towards the clamped request `r`, or `None` when
    /// the rate limit may be reached on the way.
    #[inline]
    fn step(&self, x: f64, r: f64) -> Option<f64> {
        let (rn, reach) = self.factor?;
        let d = x - r;
        (d.abs() <= reach).then_some(r + d * rn)
    }
}

/// `n` RK4 steps of length `h` of the actuator's lag from `x` towards the held request `r`.
fn lag_substeps(a: &ActuatorParams, mut x: f64, r: f64, h: f64, n: usize) -> f64 {
    let f = |x: f64| actuator::derivative(a, x, r);
    for _ in 0..n {
        let k1 = f(x);
        let k2 = f(x + 0.5 * h * k1);
        let k3 = f(x + 0.5 * h * k2);
        let k4 = f(x + h * k3);
        x += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::synth::{rig_frames, RigExperiment, SensorNoise};
    use crate::model::powertrain::Nominal;
    use crate::records::dataset::Dataset;
    use crate::records::events::SegmentOptions;

    /// Requests that step, ramp, hold, leave the actuator's range and are missing: the replay
    /// that skips the substeps of a settled actuator and takes those of the linear lag in one
    /// product gives every sample of the one that takes them all, to 1e-12 mm (rounding), and
    /// both the linear product and the rate-limited substeps are taken.
    #[test]
    fn a_settled_actuator_skips_its_substeps_and_a_linear_one_takes_them_at_once() {
        let a = Params::default().actuator;
        let mut req = Vec::new();
        for k in 0..3000 {
            let t = k as f64 * 0.01;
            req.push(match k / 300 {
                0 => 0.5,
                1 => 6.2,
                2 => 6.2 + 0.01 * (k % 300) as f64,
                3 => a.x_max_mm + 3.0,
                4 => f64::NAN,
                5 => a.x_min_mm - 1.0,
                6 => 4.0 + (t * 3.0).sin(),
                _ => 5.5,
            });
        }
        let every_substep = |x0: f64| {
            let (h, mut x) = (0.01 / 10.0, x0);
            let mut out = Vec::new();
            for (k, &r) in req.iter().enumerate() {
                out.push(x);
                if k + 1 == req.len() {
                    break;
                }
                x = lag_substeps(&a, x, r, h, 10);
                if (x - r).abs() < 1e-9 {
                    x = r;
                }
            }
            out
        };
        let linear = LinearLag::new(&a, 0.001, 10);
        for x0 in [0.5, 3.0] {
            let fast = actuator_replay(&a, &req, x0, 0.01);
            let slow = every_substep(x0);
            let worst = fast
                .iter()
                .zip(&slow)
                .map(|(f, s)| if f == s { 0.0 } else { (f - s).abs() })
                .fold(0.0, f64::max);
            assert!(worst <= 1e-12, "x0 {x0}: {worst:e} mm");
            let (mut product, mut limited) = (0, 0);
            for (k, &r) in req[..req.len() - 1].iter().enumerate() {
                let rc = actuator::clamp_request(&a, r, slow[k]);
                if rc != slow[k] {
                    match linear.step(slow[k], rc) {
                        Some(_) => product += 1,
                        None => limited += 1,
                    }
                }
            }
            assert!(
                product > 500 && limited > 5,
                "{product} linear, {limited} rate-limited"
            );
        }
    }

    /// The product is RK4's stability polynomial: at h = τ/4, R = 1 − 1/4 + 1/32 − 1/384 +
    /// 1/6144 (by hand); a step as long as the lag or longer gets no product.
    #[test]
    fn the_linear_lag_is_rk4s_stability_polynomial() {
        let mut a = Params::default().actuator;
        a.tau_s = 0.004;
        let r: f64 = 1.0 - 0.25 + 1.0 / 32.0 - 1.0 / 384.0 + 1.0 / 6144.0;
        let lin = LinearLag::new(&a, 0.001, 3);
        let x = lin
            .step(2.0, 2.0 + 0.5 * a.rate_mm_per_s * a.tau_s)
            .unwrap();
        let want = 2.0 + 0.5 * a.rate_mm_per_s * a.tau_s * (1.0 - r.powi(3));
        assert!((x - want).abs() < 1e-12, "{x} vs {want}");
        assert!(lin
            .step(2.0, 2.0 + 1.01 * a.rate_mm_per_s * a.tau_s)
            .is_none());
        a.tau_s = 0.001;
        assert!(LinearLag::new(&a, 0.001, 10).step(2.0, 2.1).is_none());
    }

    #[test]
    fn replays_reproduce_the_generating_model() {
        let p = Params::default();
        let exp = RigExperiment::identification(8, 60.0);
        let frames = rig_frames(&p, Nominal, &exp, SensorNoise::default(), 3, 0.005).unwrap();
        let truth: Vec<[f64; 2]> = frames
            .iter()
            .filter(|r| r.frame.raw_id() == u32::from(crate::can::messages::SimTruth::ID))
            .map(|r| {
                let t = crate::can::messages::SimTruth::decode(r.frame.bytes()).unwrap();
                [t.clutch1_temp_true, t.clutch2_temp_true]
            })
            .collect();
        let d = Dataset::from_records("rig", frames.into_iter().map(Ok), 0.01).unwrap();
        let m = Measured::new(&d, &p, [0.0; 2], &SegmentOptions::default());
        // Disk estimate tracks the (hidden) true disk temperature.
        let c = disk_estimate(&p, &Nominal, &m);
        let worst = (0..m.n)
            .map(|k| {
                (c[0][k] - truth[k][0])
                    .abs()
                    .max((c[1][k] - truth[k][1]).abs())
            })
            .fold(0.0, f64::max);
        assert!(worst < 1.0, "disk estimate off by {worst} °C");
        // Thermal replay follows the measured plates within a fraction of a degree.
        let r = thermal_replay(&p, &Nominal, &m);
        let worst = (0..m.n)
            .map(|k| (r[k].pp1 - m.pp[0][k]).abs().max((r[k].cd - m.cd[k]).abs()))
            .fold(0.0, f64::max);
        assert!(worst < 1.0, "thermal replay off by {worst} °C");
        // Equation-error torque matches the measurement to sensor noise.
        let mut sse = 0.0;
        let mut cnt = 0;
        for i in 0..2 {
            for &k in m.torque_idx[i].iter() {
                let e = m.torque[i][k] - torque_eq(&p, &Nominal, &m, &c, i, k);
                sse += e * e;
                cnt += 1;
            }
        }
        let rms = (sse / cnt as f64).sqrt();
        assert!(cnt > 1000 && rms < 1.0, "torque rms {rms} over {cnt}");
        // The free-running replay too (its temperatures are its own).
        let fr = full_replay(&p, &Nominal, &m);
        let e: f64 = m.torque_idx[0]
            .iter()
            .map(|&k| (fr.torque[0][k] - m.torque[0][k]).powi(2))
            .sum::<f64>()
            / m.torque_idx[0].len() as f64;
        assert!(e.sqrt() < 1.5, "replay torque rms {}", e.sqrt());
        // Actuator replay from the request.
        let xr = m.x_req[0].as_ref().unwrap();
        let xs = actuator_replay(&p.actuator, xr, m.x[0][0], m.dt);
        let worst = (0..m.n)
            .map(|k| (xs[k] - m.x[0][k]).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.03, "actuator replay off by {worst} mm");
    }

    /// The thermal replay stepping by the temperature samples' stride (0.1 s and 0.3 s) stays
    /// within 2 mK of the per-sample replay over launches heating the disks by about twenty
    /// kelvin — far below a thermocouple's 0.3 °C practical tolerance.
    #[test]
    fn thermal_replay_by_the_sample_stride_matches_the_per_sample_replay() {
        let p = Params::default();
        let exp = RigExperiment::identification(8, 60.0);
        let frames = rig_frames(&p, Nominal, &exp, SensorNoise::default(), 3, 0.005).unwrap();
        let d = Dataset::from_records("rig", frames.into_iter().map(Ok), 0.01).unwrap();
        let m = Measured::new(&d, &p, [0.0; 2], &SegmentOptions::default());
        let fine = thermal_replay(&p, &Nominal, &m);
        let rise = fine.iter().map(|s| s.c1.max(s.c2)).fold(f64::MIN, f64::max) - fine[0].c1;
        assert!(rise > 10.0, "the record heats the disks by {rise} K only");
        for stride in [10, 30] {
            let coarse = thermal_replay_every(&p, &Nominal, &m, stride);
            assert_eq!(coarse.len(), (m.n - 1) / stride + 1);
            let worst = coarse
                .iter()
                .enumerate()
                .map(|(j, c)| {
                    let f = &fine[j * stride];
                    [
                        c.pp1 - f.pp1,
                        c.pp2 - f.pp2,
                        c.c1 - f.c1,
                        c.c2 - f.c2,
                        c.cd - f.cd,
                    ]
                    .iter()
                    .fold(0.0f64, |a, d| a.max(d.abs()))
                })
                .fold(0.0, f64::max);
            eprintln!("stride {stride}: worst {worst:.2e} K over a {rise:.0} K rise");
            assert!(
                worst < 2e-3,
                "stride {stride}: {worst} K from the per-sample replay"
            );
        }
    }
}

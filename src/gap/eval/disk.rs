//! The clutch-disk temperatures θ_c1, θ_c2 estimated from the measurements: the disk equations
//! (16c)/(16d) driven by the *measured* pressure-plate, central-disk and housing temperatures and
//! the *measured* friction power (the disk temperature itself is not measured on the bench), an
//! exact exponential update per sample with the inputs at the interval midpoint. Effects act
//! through the hooks' β (engagement) and extra heat.
//!
//! A fit's Jacobian moves one parameter at a time. A parameter that acts only through β (the kiss
//! point (9), x_to,max, λ of (7), kiss-point wear) leaves the estimate exactly as it was up to the
//! first sample where β changes — and with the small steps of a finite-difference Jacobian, β
//! rarely changes at all. [`rerun_engagement`] replays only from there ([`first_change`]),
//! giving the same numbers, bit for bit, as a replay from the start.

use std::sync::Arc;

pub use crate::gap::eval::set_hooks::Heat;
use crate::gap::record::measured::Measured;
use crate::model::params::{Params, ThermalParams5};
use crate::model::powertrain::Hooks;
use crate::model::thermal::{DiskRate, Thermal5State, ThermalInputs};

/// A disk replay: the temperatures at every sample and the β each step used.
#[derive(Debug, Clone, PartialEq)]
pub struct DiskRun {
    /// θ_c of clutch 0/1 at every sample (°C).
    pub theta: Arc<[Vec<f64>; 2]>,
    /// β of clutch 0/1 over the step from sample k to k + 1 (one fewer than the samples).
    beta: Arc<[Vec<f64>; 2]>,
}

/// The thermal parameters a disk replay reads: α4…α7 of (16c)/(16d), and α3 through the heat
/// partition term when there is one (`partition`; 0 in its place when not); α1, α2, α8 and α9
/// act on the plates and the central disk, which the replay takes as measured (a test checks the
/// list against the replay under every thermal term, with and without the partition).
pub fn thermal_params(a: &ThermalParams5, partition: bool) -> [f64; 5] {
    [
        if partition { a.alpha3_k_per_j } else { 0.0 },
        a.alpha4_per_s,
        a.alpha5_per_s,
        a.alpha6_per_s,
        a.alpha7_k_per_j,
    ]
}

/// [`run`]'s temperatures.
pub fn disk_estimate<H: Hooks + ?Sized>(p: &Params, h: &H, m: &Measured) -> [Vec<f64>; 2] {
    Arc::unwrap_or_clone(run(p, h, m).theta)
}

/// The disk replay of the whole record from the measured start.
pub fn run<H: Hooks + ?Sized>(p: &Params, h: &H, m: &Measured) -> DiskRun {
    run_with(p, h, m, Heat::Hooks)
}

/// [`run`], the extra heat as `heat` says.
pub fn run_with<H: Hooks + ?Sized>(p: &Params, h: &H, m: &Measured, heat: Heat) -> DiskRun {
    let s0 = m.thermal_at(0);
    let mut theta = [Vec::with_capacity(m.n), Vec::with_capacity(m.n)];
    let mut beta = [Vec::with_capacity(m.n), Vec::with_capacity(m.n)];
    if m.n > 0 {
        theta[0].push(s0.c1);
        theta[1].push(s0.c2);
    }
    extend(p, h, m, heat, &mut theta, &mut beta);
    DiskRun {
        theta: Arc::new(theta),
        beta: Arc::new(beta),
    }
}

/// The disk replay of a model that differs from the one of `reference` only in what β reads
/// (the clutch's engagement parameters, the engagement effects): the reference's samples up to
/// the first step whose β changes, replayed from there (the extra heat as `heat` says). Equal
/// to [`run`] of the model.
pub fn rerun_engagement<H: Hooks + ?Sized>(
    p: &Params,
    h: &H,
    m: &Measured,
    reference: &DiskRun,
    heat: Heat,
) -> DiskRun {
    let k = first_change(p, h, m, reference);
    if k == reference.beta[0].len() {
        return reference.clone();
    }
    let mut theta = [0, 1].map(|i| reference.theta[i][..=k].to_vec());
    let mut beta = [0, 1].map(|i| reference.beta[i][..k].to_vec());
    extend(p, h, m, heat, &mut theta, &mut beta);
    DiskRun {
        theta: Arc::new(theta),
        beta: Arc::new(beta),
    }
}

/// The first step at which β under `h` and `p`, at the reference's temperatures, differs from
/// the reference's β (the number of steps when none does).
fn first_change<H: Hooks + ?Sized>(p: &Params, h: &H, m: &Measured, reference: &DiskRun) -> usize {
    let (theta, beta) = (&*reference.theta, &*reference.beta);
    let steps = beta[0].len().min(beta[1].len());
    let span = m.span(0, steps);
    let (th, b) = (
        [&theta[0][..steps], &theta[1][..steps]],
        [&beta[0][..steps], &beta[1][..steps]],
    );
    (0..steps)
        .find(|&k| {
            (0..2).any(|i| h.clutch_beta(&p.clutch, &span.context(i, k, th[i][k])) != b[i][k])
        })
        .unwrap_or(steps)
}

/// Continues a replay (temperatures up to some sample k, β up to step k − 1) to the end of the
/// record.
fn extend<H: Hooks + ?Sized>(
    p: &Params,
    h: &H,
    m: &Measured,
    heat: Heat,
    theta: &mut [Vec<f64>; 2],
    beta_out: &mut [Vec<f64>; 2],
) {
    if heat == Heat::Zero {
        return extend_zero_heat(p, h, m, theta, beta_out);
    }
    let a = &p.thermal5;
    let n = m.n;
    let Some(k0) = theta[0].len().checked_sub(1) else {
        return;
    };
    let mut c = [theta[0][k0], theta[1][k0]];
    // e^{−λ·dt} of the last λ per clutch: λ changes only when β does (a clutch closing or
    // opening), so the exponential is taken a few times per engagement, not per sample.
    let mut decay = [(f64::NAN, 0.0); 2];
    let span = m.span(0, n);
    let wf = &m.w_f[..n];
    let Series { th, cd, pp, pw } = Series::of(m, n);
    for k in k0..n - 1 {
        let mid = |v: &[f64]| 0.5 * (v[k] + v[k + 1]);
        let (th_m, cd_m) = (mid(th), mid(cd));
        let pp_m = [mid(pp[0]), mid(pp[1])];
        // Not clamped at zero: sensor noise on an open clutch must average out, not heat.
        let pw_m = [mid(pw[0]), mid(pw[1])];
        // Written out, not `[0, 1].map(…)`: the array map's closure is not inlined, a call per
        // step on the step's dependency chain.
        let beta = [
            h.clutch_beta(&p.clutch, &span.context(0, k, c[0])),
            h.clutch_beta(&p.clutch, &span.context(1, k, c[1])),
        ];
        let state = Thermal5State {
            pp1: pp_m[0],
            pp2: pp_m[1],
            c1: c[0],
            c2: c[1],
            cd: cd_m,
        };
        let tin = ThermalInputs {
            p_fric1_w: pw_m[0],
            p_fric2_w: pw_m[1],
            beta1: beta[0],
            beta2: beta[1],
            theta_h_c: th_m,
            w_f_radps: mid(wf),
        };
        let extra = h.extra_heat(&state, &tin);
        for i in 0..2 {
            let b = beta[i];
            let r = DiskRate::new(a, b);
            let lam = r.lam;
            let g = r.g(pp_m[i], cd_m, th_m, pw_m[i]) + if i == 0 { extra.c1 } else { extra.c2 };
            c[i] = exact_step(c[i], lam, g, m.dt, || {
                if decay[i].0 != lam {
                    decay[i] = (lam, (-lam * m.dt).exp());
                }
                decay[i].1
            });
            theta[i].push(c[i]);
            beta_out[i].push(b);
        }
    }
}

/// [`extend`] for hooks without extra heat ([`Heat::Zero`]), the same numbers with a shorter
/// chain from one sample's temperature to the next: λ and its decay are worked out once for
/// each value of β, and the step's update takes β's value of the step before unless β has
/// changed — a branch the processor predicts, so the update does not wait for β, which is
/// computed beside it (a β other than 0 or 1 from other hooks takes the step as [`extend`]
/// writes it). Out of line: the loop's code does not depend on what it is inlined into.
#[inline(never)]
fn extend_zero_heat<H: Hooks + ?Sized>(
    p: &Params,
    h: &H,
    m: &Measured,
    theta: &mut [Vec<f64>; 2],
    beta_out: &mut [Vec<f64>; 2],
) {
    const B: [f64; 3] = [0.0, 1.0, f64::NAN];
    let a = &p.thermal5;
    let n = m.n;
    let Some(k0) = theta[0].len().checked_sub(1) else {
        return;
    };
    let c = [theta[0][k0], theta[1][k0]];
    let rate = [DiskRate::new(a, B[0]), DiskRate::new(a, B[1])];
    let decay = rate.map(|r| (-r.lam * m.dt).exp());
    let exact = rate.map(|r| r.lam * m.dt > 1e-9);
    // The index in B of each clutch's β at the step before (2: none yet, or another value).
    let j = [2usize; 2];
    let span = m.span(0, n);
    let Series { th, cd, pp, pw } = Series::of(m, n);
    // One clutch after the other: the clutches' steps do not depend on each other, and a loop
    // over one keeps less state live (both in one loop spilled it to the stack); the 30-minute
    // diagnosis took 4.4 s instead of 4.6 s on the 2-core machine.
    for i in 0..2 {
        let (pp, pw) = (pp[i], pw[i]);
        let (theta, beta_out) = (&mut theta[i], &mut beta_out[i]);
        let mut c = c[i];
        let mut j = j[i];
        for k in k0..n - 1 {
            let mid = |v: &[f64]| 0.5 * (v[k] + v[k + 1]);
            let (th_m, cd_m, pp_m, pw_m) = (mid(th), mid(cd), mid(pp), mid(pw));
            let b = h.clutch_beta(&p.clutch, &span.context(i, k, c));
            if b.to_bits() != B[j].to_bits() {
                j = beta_index(b);
            }
            c = if j < 2 && exact[j] {
                let inf = rate[j].g(pp_m, cd_m, th_m, pw_m) / rate[j].lam;
                inf + (c - inf) * decay[j]
            } else {
                let r = DiskRate::new(a, b);
                exact_step(c, r.lam, r.g(pp_m, cd_m, th_m, pw_m), m.dt, || {
                    (-r.lam * m.dt).exp()
                })
            };
            theta.push(c);
            beta_out.push(b);
        }
    }
}

/// θ after a step `dt` of θ̇ = −λθ + g from `c`: exact with the decay e^{−λ·dt} (`decay`, asked
/// only then), Euler where λ·dt is too small for the exponential form.
#[inline(always)]
fn exact_step(c: f64, lam: f64, g: f64, dt: f64, decay: impl FnOnce() -> f64) -> f64 {
    if lam * dt > 1e-9 {
        let inf = g / lam;
        inf + (c - inf) * decay()
    } else {
        c + (g - lam * c) * dt
    }
}

/// The measured series both replay loops read, cut at `n` samples: housing air, central disk,
/// pressure plates and friction powers.
struct Series<'a> {
    th: &'a [f64],
    cd: &'a [f64],
    pp: [&'a [f64]; 2],
    pw: [&'a [f64]; 2],
}

impl<'a> Series<'a> {
    fn of(m: &'a Measured, n: usize) -> Self {
        Series {
            th: &m.th[..n],
            cd: &m.cd[..n],
            pp: [&m.pp[0][..n], &m.pp[1][..n]],
            pw: [&m.power[0][..n], &m.power[1][..n]],
        }
    }
}

/// The index of `b` in [`extend_zero_heat`]'s values of β (0.0, 1.0, the bits alike; 2 for any
/// other): out of line, the rare step where β changes.
#[cold]
#[inline(never)]
fn beta_index(b: f64) -> usize {
    if b.to_bits() == 0.0f64.to_bits() {
        0
    } else if b.to_bits() == 1.0f64.to_bits() {
        1
    } else {
        2
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::record::measured::test_record;
    use crate::model::effects::{EffectId, EffectSet};
    use crate::model::powertrain::Nominal;

    fn bits(r: &DiskRun) -> Vec<u64> {
        r.theta.iter().flatten().map(|v| v.to_bits()).collect()
    }

    /// Kiss points moved by a Jacobian's step, by tenths of a millimetre, by wear: the replay
    /// resumed where β first changes is the replay from the start, bit for bit; a step too small
    /// to change β anywhere leaves the reference as it is.
    #[test]
    fn a_resumed_replay_is_the_replay_from_the_start() {
        let p = Params::default();
        let m = test_record(&p);
        let reference = run(&p, &Nominal, &m);
        assert_eq!(reference.theta[0].len(), m.n);
        assert_eq!(reference.beta[0].len(), m.n - 1);
        let moved = |f: &dyn Fn(&mut Params)| {
            let mut q = p;
            f(&mut q);
            q
        };
        let tiny = moved(&|q| q.clutch.x_isp0_mm *= 1.0 + 1e-9);
        assert_eq!(first_change(&tiny, &Nominal, &m, &reference), m.n - 1);
        assert_eq!(
            bits(&rerun_engagement(
                &tiny,
                &Nominal,
                &m,
                &reference,
                Heat::Hooks
            )),
            bits(&reference)
        );
        for q in [
            moved(&|q| q.clutch.x_isp0_mm += 0.3),
            moved(&|q| q.clutch.x_isp0_mm -= 0.2),
            moved(&|q| q.clutch.x_isp1_mm_per_c *= 3.0),
        ] {
            let k = first_change(&q, &Nominal, &m, &reference);
            assert!(k < m.n - 1, "β changes somewhere on this record ({q:?})");
            let resumed = rerun_engagement(&q, &Nominal, &m, &reference, Heat::Hooks);
            assert_eq!(bits(&resumed), bits(&run(&q, &Nominal, &m)));
            assert_ne!(bits(&resumed), bits(&reference));
        }
        // An engagement effect, through the hooks.
        let wear = crate::gap::eval::set_hooks::SetHooks(
            EffectSet::single(EffectId::KissPointWear, &[0.02]).unwrap(),
            None,
        );
        let resumed = rerun_engagement(&p, &wear, &m, &reference, Heat::Hooks);
        assert_eq!(bits(&resumed), bits(&run(&p, &wear, &m)));
    }

    /// Hooks without extra heat: the replay that adds zero without asking them ([`Heat::Zero`])
    /// is the one that asks, bit for bit — from the start and resumed, at moved kiss points,
    /// under an engagement effect, at a rate λ·dt below the exact update's threshold (the Euler
    /// step) — and [`SetHooks::heat`](crate::gap::eval::set_hooks::SetHooks::heat) says `Zero` exactly
    /// when the hooks' extra heat is zero in every state.
    #[test]
    fn a_replay_without_extra_heat_is_the_one_that_asks() {
        use crate::gap::eval::set_hooks::SetHooks;
        use crate::gap::model::terms::{Partition, ThermalTerms};
        let p = Params::default();
        let m = test_record(&p);
        let moved = |f: &dyn Fn(&mut Params)| {
            let mut q = p;
            f(&mut q);
            q
        };
        let wear = EffectSet::single(EffectId::KissPointWear, &[0.02]).unwrap();
        let pressure = EffectSet::single(EffectId::FrictionPressure, &[0.9]).unwrap();
        let slow = moved(&|q| q.thermal5.alpha6_per_s = 1e-9);
        // Each model with the nominal one of the same heat flows, to resume from.
        for (q, h, r) in [
            (p, SetHooks::default(), p),
            (
                moved(&|q| q.clutch.x_isp0_mm += 0.3),
                SetHooks::default(),
                p,
            ),
            (p, SetHooks(wear, None), p),
            (p, SetHooks(pressure, None), p),
            (slow, SetHooks::default(), slow),
        ] {
            assert_eq!(h.heat(), Heat::Zero, "{h:?}");
            let asks = bits(&run(&q, &h, &m));
            assert!(
                bits(&run_with(&q, &h, &m, Heat::Zero)) == asks,
                "{q:?} {h:?}"
            );
            let reference = run(&r, &Nominal, &m);
            let resumed = rerun_engagement(&q, &h, &m, &reference, Heat::Zero);
            assert!(bits(&resumed) == asks, "resumed: {q:?} {h:?}");
        }
        let support = EffectSet::single(EffectId::SupportConduction, &[0.01]).unwrap();
        let partition = ThermalTerms {
            a: p.thermal5,
            support: None,
            convection: None,
            partition: Some(Partition {
                shape: crate::gap::model::shape::Shape {
                    z: std::array::from_fn(|j| j as f64 * 3000.0),
                    v: [0.2; crate::gap::model::shape::KNOTS],
                },
                w_c: 1.5,
            }),
        };
        for h in [SetHooks(support, None), SetHooks(pressure, Some(partition))] {
            assert_eq!(h.heat(), Heat::Hooks, "{h:?}");
            assert_ne!(
                bits(&run(&p, &h, &m)),
                bits(&run(&p, &SetHooks::default(), &m))
            );
        }
    }

    /// Each thermal parameter moved by 20 %, under the support and convection terms with and
    /// without the partition term: the disk replay moves exactly when the parameter is one of
    /// [`thermal_params`].
    #[test]
    fn the_replay_reads_exactly_its_thermal_params() {
        use crate::gap::model::shape::Shape;
        use crate::gap::model::terms::{Convection, Partition, Support, ThermalTerms};
        let p = Params::default();
        let m = test_record(&p);
        let shape = |z0: f64, z1: f64, v: f64| {
            let z: [f64; crate::gap::model::shape::KNOTS] =
                std::array::from_fn(|j| z0 + (z1 - z0) * j as f64 / 6.0);
            Shape {
                z,
                v: std::array::from_fn(|j| v * j as f64 / 6.0),
            }
        };
        for partition in [true, false] {
            let hooks = |a: ThermalParams5| {
                crate::gap::eval::set_hooks::SetHooks(
                    EffectSet::nominal(),
                    Some(ThermalTerms {
                        a,
                        support: Some(Support {
                            shape: shape(0.0, 200.0, 0.02),
                            w_pp: 0.5,
                            w_cd: 0.5,
                        }),
                        convection: Some(Convection {
                            shape: shape(0.0, 400.0, 0.5),
                        }),
                        partition: partition.then_some(Partition {
                            shape: shape(0.0, 20000.0, 0.3),
                            w_c: 1.5,
                        }),
                    }),
                )
            };
            let base = bits(&run(&p, &hooks(p.thermal5), &m));
            let table = toml::Table::try_from(p.thermal5).unwrap();
            for key in table.keys() {
                let mut t = table.clone();
                let v = t[key].as_float().unwrap();
                t[key] = toml::Value::Float(if v == 0.0 { 0.01 } else { v * 1.2 });
                let a: ThermalParams5 = t.try_into().unwrap();
                let mut q = p;
                q.thermal5 = a;
                let moved = bits(&run(&q, &hooks(a), &m)) != base;
                let listed =
                    thermal_params(&a, partition) != thermal_params(&p.thermal5, partition);
                assert_eq!(
                    moved, listed,
                    "{key} (partition {partition}): the replay moved {moved}, listed {listed}"
                );
            }
        }
    }
}

//! [`thermal_replay_every`](crate::gap::eval::replay::thermal_replay_every) of a model with the library's β
//! and no engagement effect ([`thermal_replay_fast`]), the same numbers bit for bit with less
//! work per step:
//! - the inputs a step averages over its window (friction power, housing temperature, flywheel
//!   speed) do not depend on the model: they are computed once per record and stride
//!   ([`Windows`], [`PowerMeans`](crate::gap::record::windows::PowerMeans), kept by the record:
//!   [`Measured::windows`]);
//! - β of (16) at the step's starting state is 1 where the flat spring is compressed, u_fs > 0 of
//!   (7): at a fixed disk temperature a step function of x_to that never falls as x_to rises
//!   (every operation of u_fs is monotone in x_to for λ ≥ 0; an energy-driven kiss-point shift,
//!   [`ENGAGEMENT_EFFECTS`], would break this). With each window's samples ordered by x_to once,
//!   the number of engaged samples — the sum of the per-sample β of 0.0 and 1.0, exact in f64 — is
//!   found by bisection: about five evaluations of β per window and clutch instead of one per
//!   sample.
//!
//! Any other model takes the straightforward replay.

use crate::gap::eval::replay;
use crate::gap::eval::set_hooks::SetHooks;
use crate::gap::record::measured::Measured;
use crate::gap::record::windows::{Sample, Windows};
use crate::model::effects::ENGAGEMENT_EFFECTS;
use crate::model::params::Params;
use crate::model::powertrain::{ClutchContext, Hooks};
use crate::model::thermal::Thermal5State;

/// Whether [`thermal_replay_fast`] may count β by bisection for the hooks `h` and parameters
/// `p`: no engagement effect, λ ≥ 0 (u_fs then monotone in x_to).
fn bisects(p: &Params, h: &SetHooks) -> bool {
    h.0.only(&ENGAGEMENT_EFFECTS).is_nominal() && p.clutch.lambda >= 0.0
}

/// [`replay::thermal_replay_every`] of `p` under `h` on `m`, bit for bit, from the record's
/// windows when [`bisects`] allows.
pub fn thermal_replay_fast(
    p: &Params,
    h: &SetHooks,
    m: &Measured,
    stride: usize,
) -> Vec<Thermal5State> {
    if !bisects(p, h) {
        return replay::thermal_replay_every(p, h, m, stride);
    }
    let stride = stride.max(1);
    let win = m.windows(stride);
    let power = m.power_means(stride);
    replay::replay_windows(p, h, m, stride, |k0, k1, s| {
        let w = k0 / stride;
        let len = (k1 - k0) as f64;
        let [th, w_f] = win.means(w);
        let mut u = replay::inputs(power.at(w), th, w_f);
        u.beta1 = engaged(p, h, m, &win, s, 0, w) as f64 / len;
        u.beta2 = engaged(p, h, m, &win, s, 1, w) as f64 / len;
        u
    })
}

/// The number of samples of window `w` at which clutch `i` is engaged at the state `s`: β
/// evaluated as [`replay::thermal_replay_every`] evaluates it, at the window's ends first, the
/// first engaged sample found by bisection where they differ.
fn engaged(
    p: &Params,
    h: &SetHooks,
    m: &Measured,
    win: &Windows,
    s: &Thermal5State,
    i: usize,
    w: usize,
) -> usize {
    let ordered = win.ordered(i, w);
    if ordered.is_empty() {
        return 0;
    }
    let (theta_c, theta_pp) = if i == 0 { (s.c1, s.pp1) } else { (s.c2, s.pp2) };
    let open = |x: &Sample| {
        let ctx = ClutchContext {
            clutch: i,
            x_to_mm: x.x_to_mm,
            slip_radps: x.slip_radps,
            theta_c,
            theta_pp,
            theta_cd: s.cd,
            e_fric_j: x.e_fric_j,
        };
        h.clutch_beta(&p.clutch, &ctx) == 0.0
    };
    let [lo, hi] = win.ends(i, w);
    if open(hi) {
        0
    } else if !open(lo) {
        ordered.len()
    } else {
        ordered.len() - ordered.partition_point(|k| open(&sample(m, i, *k as usize)))
    }
}

/// What a clutch context reads of `m` at sample `k` of clutch `i`.
fn sample(m: &Measured, i: usize, k: usize) -> Sample {
    Sample {
        x_to_mm: m.x[i][k],
        slip_radps: m.slip[i][k],
        e_fric_j: m.e_cum[i][k],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::model::terms::{Convection, ThermalTerms};
    use crate::gap::record::measured::test_record;
    use crate::model::effects::{EffectId, EffectSet};

    fn bits(v: &[Thermal5State]) -> Vec<u64> {
        v.iter()
            .flat_map(|s| [s.pp1, s.pp2, s.c1, s.c2, s.cd])
            .map(f64::to_bits)
            .collect()
    }

    /// Kiss points moved so that windows switch engagement within themselves, a speed-dependent
    /// convection term, an engagement effect (the straightforward replay), NaN positions, another
    /// friction power on a clone of the record, strides from 1 to past a window's engagement:
    /// the replay from the windows is the straightforward one bit for bit, and a record keeps one
    /// set of windows per stride.
    #[test]
    fn the_windowed_replay_is_the_straightforward_one() {
        let p = Params::default();
        let mut m = test_record(&p);
        let mut x0 = m.x[0].to_vec();
        for k in (100..m.n).step_by(997) {
            x0[k] = f64::NAN;
        }
        m.x[0] = x0.into();
        let moved = |f: &dyn Fn(&mut Params)| {
            let mut q = p;
            f(&mut q);
            q
        };
        let convection = Some(ThermalTerms {
            a: p.thermal5,
            support: None,
            convection: Some(Convection {
                shape: crate::gap::model::shape::Shape {
                    z: std::array::from_fn(|j| j as f64 * 60.0),
                    v: std::array::from_fn(|j| 0.1 * j as f64),
                },
            }),
            partition: None,
        });
        let wear = EffectSet::single(EffectId::KissPointWear, &[0.02]).unwrap();
        let cases = [
            (p, SetHooks(EffectSet::nominal(), None)),
            (moved(&|q| q.clutch.x_isp0_mm += 0.4), SetHooks::default()),
            (
                moved(&|q| q.clutch.x_isp1_mm_per_c *= 3.0),
                SetHooks::default(),
            ),
            (p, SetHooks(EffectSet::nominal(), convection)),
            (p, SetHooks(wear, None)),
        ];
        let power = [
            m.power[0].clone(),
            m.power[1].iter().map(|w| 1.3 * w).collect(),
        ];
        let other = m.clone().with_power(power, m.e_cum.clone());
        let mut mixed = 0;
        for stride in [1, 7, 10, 23, 100] {
            for (q, h) in &cases {
                for r in [&m, &other] {
                    let fast = thermal_replay_fast(q, h, r, stride);
                    let slow = replay::thermal_replay_every(q, h, r, stride);
                    assert_eq!(bits(&fast), bits(&slow), "stride {stride}, {q:?}, {h:?}");
                }
            }
            let win = m.windows(stride);
            mixed += (0..win.len())
                .filter(|&w| {
                    let n = engaged(&p, &cases[0].1, &m, &win, &m.start, 0, w);
                    n > 0 && n < win.ordered(0, w).len()
                })
                .count();
        }
        assert!(mixed > 0, "no window switches engagement within itself");
        assert!(
            bits(&thermal_replay_fast(&p, &cases[0].1, &m, 23))
                != bits(&thermal_replay_fast(&p, &cases[0].1, &other, 23))
        );
    }
}

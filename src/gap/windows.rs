//! [`thermal_replay_every`](super::replay::thermal_replay_every) of a model with the library's β
//! and no engagement effect ([`thermal_replay_fast`]), the same numbers bit for bit with less
//! work per step:
//! - the inputs a step averages over its window (friction power, housing temperature, flywheel
//!   speed) do not depend on the model: they are computed once per record and stride
//!   ([`Windows`], kept in the record's [`WindowCache`]);
//! - β of (16) at the step's starting state is 1 where the flat spring is compressed, u_fs > 0 of
//!   (7): at a fixed disk temperature a step function of x_to that never falls as x_to rises
//!   (every operation of u_fs is monotone in x_to for λ ≥ 0; an energy-driven kiss-point shift,
//!   [`ENGAGEMENT_EFFECTS`], would break this). With each window's samples ordered by x_to once,
//!   the number of engaged samples — the sum of the per-sample β of 0.0 and 1.0, exact in f64 — is
//!   found by bisection: about five evaluations of β per window and clutch instead of one per
//!   sample.
//!
//! Any other model takes the straightforward replay.

use std::sync::Arc;

use super::record_cache::RecordCache;

use super::candidates::SetHooks;
use super::replay::{self, Measured, Shared};
use crate::model::effects::ENGAGEMENT_EFFECTS;
use crate::model::params::Params;
use crate::model::powertrain::{ClutchContext, Hooks};
use crate::model::thermal::{Thermal5State, ThermalInputs};

/// A record's [`Windows`], one per stride asked for; clones of a [`Measured`] share it.
#[derive(Debug, Clone, Default)]
pub struct WindowCache(RecordCache<Windows>);

/// The model-free part of the steps of a replay at one stride.
#[derive(Debug)]
pub struct Windows {
    stride: usize,
    /// The series the windows were computed from (a clone of the record with other inputs, a
    /// sensor class's corrected power, say, must not take them).
    x: [Shared; 2],
    power: [Shared; 2],
    th: Shared,
    w_f: Shared,
    /// Per window: the mean friction power of each clutch, housing temperature, flywheel speed.
    means: Vec<[f64; 4]>,
    /// Per clutch, each window's samples (record indices) by ascending x_to; NaN positions
    /// (never engaged: u_fs of NaN is 0) left out, so a window's list may be shorter.
    order: [Vec<u32>; 2],
    /// Per clutch, where each window's list starts in `order` (one more entry than windows).
    start: [Vec<u32>; 2],
    /// Per clutch and window, what a clutch context reads of the record (x_to, slip, energy) at
    /// the window's lowest and highest x_to: most windows are decided by these two alone, read
    /// here in order instead of from wherever they are in the record.
    ends: [Vec<[Sample; 2]>; 2],
}

/// What a clutch context reads of the record at one sample.
#[derive(Debug, Clone, Copy)]
struct Sample {
    x_to_mm: f64,
    slip_radps: f64,
    e_fric_j: f64,
}

impl Sample {
    fn of(m: &Measured, i: usize, k: usize) -> Sample {
        Sample {
            x_to_mm: m.x[i][k],
            slip_radps: m.slip[i][k],
            e_fric_j: m.e_cum[i][k],
        }
    }
}

impl Windows {
    /// The windows of `m` at `stride` (≥ 1), as [`replay::replay_windows`] steps.
    fn new(m: &Measured, stride: usize) -> Windows {
        let mut means = Vec::with_capacity(m.n / stride + 1);
        let mut order = [Vec::with_capacity(m.n), Vec::with_capacity(m.n)];
        let mut start = [vec![0u32], vec![0u32]];
        let mut ends = [Vec::new(), Vec::new()];
        let mut k0 = 0;
        while k0 + stride < m.n {
            let k1 = k0 + stride;
            let mean = |v: &[f64]| replay::window_mean(v, k0, k1);
            means.push([
                mean(&m.power[0]),
                mean(&m.power[1]),
                mean(&m.th),
                mean(&m.w_f),
            ]);
            for i in 0..2 {
                let x = &m.x[i];
                let from = order[i].len();
                order[i].extend((k0..k1).filter(|&k| !x[k].is_nan()).map(|k| k as u32));
                order[i][from..].sort_by(|&a, &b| x[a as usize].total_cmp(&x[b as usize]));
                start[i].push(order[i].len() as u32);
                if let (Some(&lo), Some(&hi)) = (order[i][from..].first(), order[i].last()) {
                    ends[i].push([lo, hi].map(|k| Sample::of(m, i, k as usize)));
                } else {
                    ends[i].push([Sample::of(m, i, k0); 2]);
                }
            }
            k0 = k1;
        }
        Windows {
            stride,
            x: m.x.clone(),
            power: m.power.clone(),
            th: m.th.clone(),
            w_f: m.w_f.clone(),
            means,
            order,
            start,
            ends,
        }
    }

    /// Whether these are the windows of `m` at `stride` (the power aside: see [`Self::inputs`]).
    fn of(&self, m: &Measured, stride: usize) -> bool {
        let same = |a: &Shared, b: &Shared| Arc::ptr_eq(a, b);
        self.stride == stride
            && same(&self.x[0], &m.x[0])
            && same(&self.x[1], &m.x[1])
            && same(&self.th, &m.th)
            && same(&self.w_f, &m.w_f)
    }

    /// The averaged inputs of window `w` (β unset); the friction power averaged again when `m`'s
    /// is not the one the windows were made from.
    fn inputs(&self, m: &Measured, w: usize, k0: usize, k1: usize) -> ThermalInputs {
        let [p0, p1, th, wf] = self.means[w];
        let own = |i: usize| Arc::ptr_eq(&self.power[i], &m.power[i]);
        let pw = [
            if own(0) {
                p0
            } else {
                replay::window_mean(&m.power[0], k0, k1)
            },
            if own(1) {
                p1
            } else {
                replay::window_mean(&m.power[1], k0, k1)
            },
        ];
        replay::inputs(pw, th, wf)
    }

    /// The samples of window `w` of clutch `i` by ascending x_to.
    fn ordered(&self, i: usize, w: usize) -> &[u32] {
        &self.order[i][self.start[i][w] as usize..self.start[i][w + 1] as usize]
    }
}

impl WindowCache {
    /// The windows of `m` at `stride`, made on first use.
    fn get(&self, m: &Measured, stride: usize) -> Arc<Windows> {
        self.0.get(|w| w.of(m, stride), || Windows::new(m, stride))
    }
}

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
    let win = m.windows.get(m, stride);
    replay::replay_windows(p, h, m, stride, |k0, k1, s| {
        let w = k0 / stride;
        let len = (k1 - k0) as f64;
        let mut u = win.inputs(m, w, k0, k1);
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
    let [lo, hi] = &win.ends[i][w];
    if open(hi) {
        0
    } else if !open(lo) {
        ordered.len()
    } else {
        ordered.len() - ordered.partition_point(|k| open(&Sample::of(m, i, *k as usize)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::replay::test_record;
    use crate::gap::terms::{Convection, ThermalTerms};
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
                shape: crate::gap::shape::Shape {
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
        let mut other = m.clone();
        other.power[1] = other.power[1].iter().map(|w| 1.3 * w).collect();
        let mut mixed = 0;
        for stride in [1, 7, 10, 23, 100] {
            for (q, h) in &cases {
                for r in [&m, &other] {
                    let fast = thermal_replay_fast(q, h, r, stride);
                    let slow = replay::thermal_replay_every(q, h, r, stride);
                    assert_eq!(bits(&fast), bits(&slow), "stride {stride}, {q:?}, {h:?}");
                }
            }
            let win = m.windows.get(&m, stride);
            mixed += (0..win.means.len())
                .filter(|&w| {
                    let n = engaged(&p, &cases[0].1, &m, &win, &m.start, 0, w);
                    n > 0 && n < win.ordered(0, w).len()
                })
                .count();
        }
        assert!(mixed > 0, "no window switches engagement within itself");
        assert_eq!(m.windows.0.len(), 5);
        assert!(
            bits(&thermal_replay_fast(&p, &cases[0].1, &m, 23))
                != bits(&thermal_replay_fast(&p, &cases[0].1, &other, 23))
        );
    }
}

//! The model-free part of the thermal replay's steps at one stride ([`Windows`]): the inputs a
//! step averages over its window (housing temperature, flywheel speed; the friction power apart,
//! [`PowerMeans`], since a torque-sensor correction replaces it), and each window's samples
//! ordered by x_to, with what a clutch context reads at the lowest and highest, for the β count
//! by bisection of the fast thermal replay (`gap::eval::fast_replay`). Computed once per record and stride
//! ([`crate::gap::record::measured::Measured::windows`]), from the record's series alone.

use crate::gap::record::series::window_mean;
use std::sync::Arc;

/// The series of a record the windows are made from.
#[derive(Debug, Clone, Copy)]
pub struct WindowSeries<'a> {
    pub x: [&'a [f64]; 2],
    pub slip: [&'a [f64]; 2],
    pub e_cum: [&'a [f64]; 2],
    pub th: &'a [f64],
    pub w_f: &'a [f64],
}

/// Each window's samples of a replay at one stride by ascending x_to, per clutch: a function of
/// the positions alone, so a speed-sensor correction of the record keeps it
/// ([`crate::gap::record::measured::Measured::with_speeds`]).
#[derive(Debug)]
pub struct XOrder {
    /// Per clutch, each window's samples (record indices) by ascending x_to; NaN positions
    /// (never engaged: u_fs of NaN is 0) left out, so a window's list may be shorter.
    order: [Vec<u32>; 2],
    /// Per clutch, where each window's list starts in `order` (one more entry than windows).
    start: [Vec<u32>; 2],
    stride: usize,
}

impl XOrder {
    /// The order of the positions `x` in the windows of `stride` (≥ 1) samples.
    pub fn new(x: [&[f64]; 2], stride: usize) -> XOrder {
        let n = x[0].len();
        let mut order = [Vec::with_capacity(n), Vec::with_capacity(n)];
        let mut start = [vec![0u32], vec![0u32]];
        let mut k0 = 0;
        while k0 + stride < n {
            let k1 = k0 + stride;
            for i in 0..2 {
                let x = x[i];
                let from = order[i].len();
                order[i].extend((k0..k1).filter(|&k| !x[k].is_nan()).map(|k| k as u32));
                order[i][from..].sort_by(|&a, &b| x[a as usize].total_cmp(&x[b as usize]));
                start[i].push(order[i].len() as u32);
            }
            k0 = k1;
        }
        XOrder {
            order,
            start,
            stride,
        }
    }

    /// The samples of window `w` of clutch `i` by ascending x_to.
    fn ordered(&self, i: usize, w: usize) -> &[u32] {
        &self.order[i][self.start[i][w] as usize..self.start[i][w + 1] as usize]
    }
}

/// The windows of a replay at one stride: sample `k0 = w·stride` to `k1 = k0 + stride` for each
/// window `w` with `k1` inside the record.
#[derive(Debug)]
pub struct Windows {
    /// Per window: the mean housing temperature and flywheel speed.
    means: Vec<[f64; 2]>,
    /// Each window's samples by ascending x_to.
    order: Arc<XOrder>,
    /// Per clutch and window, what a clutch context reads of the record (x_to, slip, energy) at
    /// the window's lowest and highest x_to: most windows are decided by these two alone, read
    /// here in order instead of from wherever they are in the record.
    ends: [Vec<[Sample; 2]>; 2],
}

/// What a clutch context reads of the record at one sample.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    pub x_to_mm: f64,
    pub slip_radps: f64,
    pub e_fric_j: f64,
}

impl Sample {
    /// Clutch `i` at sample `k` of `s`.
    pub fn of(s: &WindowSeries<'_>, i: usize, k: usize) -> Sample {
        Sample {
            x_to_mm: s.x[i][k],
            slip_radps: s.slip[i][k],
            e_fric_j: s.e_cum[i][k],
        }
    }
}

impl Windows {
    /// The windows of `s` at the stride of `order`, the order of `s.x` in them
    /// ([`XOrder::new`]), as `gap::eval::replay::replay_windows` steps.
    pub fn new(s: &WindowSeries<'_>, order: Arc<XOrder>) -> Windows {
        let (windows, stride) = (order.start[0].len() - 1, order.stride);
        let mut means = Vec::with_capacity(windows);
        let mut ends = [Vec::with_capacity(windows), Vec::with_capacity(windows)];
        for w in 0..windows {
            let (k0, k1) = (w * stride, (w + 1) * stride);
            means.push([window_mean(s.th, k0, k1), window_mean(s.w_f, k0, k1)]);
            for (i, ends) in ends.iter_mut().enumerate() {
                let o = order.ordered(i, w);
                ends.push(match (o.first(), o.last()) {
                    (Some(&lo), Some(&hi)) => [lo, hi].map(|k| Sample::of(s, i, k as usize)),
                    _ => [Sample::of(s, i, k0); 2],
                });
            }
        }
        Windows { means, order, ends }
    }

    /// Number of windows.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// Whether there is none (a record shorter than a stride).
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// The mean housing temperature and flywheel speed over window `w`.
    pub fn means(&self, w: usize) -> [f64; 2] {
        self.means[w]
    }

    /// The samples of window `w` of clutch `i` by ascending x_to.
    pub fn ordered(&self, i: usize, w: usize) -> &[u32] {
        self.order.ordered(i, w)
    }

    /// What a clutch context reads at the lowest and highest x_to of window `w` of clutch `i`.
    pub fn ends(&self, i: usize, w: usize) -> &[Sample; 2] {
        &self.ends[i][w]
    }
}

/// Each clutch's mean friction power over the windows of one stride (as [`Windows`]).
#[derive(Debug)]
pub struct PowerMeans(Vec<[f64; 2]>);

impl PowerMeans {
    /// The means of each clutch's power `power` over the windows of `stride` (≥ 1) samples.
    pub fn new(power: [&[f64]; 2], stride: usize) -> PowerMeans {
        let n = power[0].len();
        let mut means = Vec::with_capacity(n / stride + 1);
        let mut k0 = 0;
        while k0 + stride < n {
            let k1 = k0 + stride;
            means.push(power.map(|p| window_mean(p, k0, k1)));
            k0 = k1;
        }
        PowerMeans(means)
    }

    /// Each clutch's mean power over window `w` (W).
    pub fn at(&self, w: usize) -> [f64; 2] {
        self.0[w]
    }
}

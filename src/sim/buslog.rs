//! Analysis of a recorded bus (a candump log or the frames of a run): the rows the metrics need
//! (one per TCU_Status frame, i.e. per TCU cycle, with the latest value of every message), the
//! latency from a DCT_Sensors frame to the TCU_ClutchCmd frame it causes, and the cycle jitter of
//! a message — all from the recorder's receive timestamps (the kernel's on SocketCAN).

use super::{BusView, Row};
use crate::can::messages::ids;
use crate::can::CanFrame;
use serde::Serialize;
use std::time::Duration;

/// Percentiles of a set of durations (µs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct Spread {
    pub n: usize,
    pub p50_us: f64,
    pub p99_us: f64,
    pub max_us: f64,
}

impl Spread {
    pub fn of(mut us: Vec<f64>) -> Spread {
        us.retain(|v| v.is_finite());
        if us.is_empty() {
            return Spread::default();
        }
        us.sort_by(f64::total_cmp);
        let q = |p: f64| {
            let rank = ((p * us.len() as f64).ceil() as usize).clamp(1, us.len());
            us[rank - 1]
        };
        Spread {
            n: us.len(),
            p50_us: q(0.5),
            p99_us: q(0.99),
            max_us: q(1.0),
        }
    }
}

/// Rows of a recorded bus: one per TCU_Status frame once the plant's sensors have been seen,
/// times relative to the first frame.
pub fn rows(frames: &[(Duration, CanFrame)]) -> Vec<Row> {
    let t0 = frames.first().map_or(Duration::ZERO, |f| f.0);
    let mut view = BusView::default();
    let mut out = Vec::new();
    let mut plant_seen = false;
    for (t, f) in frames {
        view.take(f);
        plant_seen |= f.standard_id() == Some(ids::DCT_SENSORS);
        if f.standard_id() == Some(ids::TCU_STATUS) && plant_seen {
            let mut r = view.row;
            r.t_s = t.saturating_sub(t0).as_secs_f64();
            out.push(r);
        }
    }
    out
}

/// Latency from each `cause` frame to the first `effect` frame after it and before the next
/// `cause` frame (µs); causes without an effect are counted as `missed`.
pub fn latency(frames: &[(Duration, CanFrame)], cause: u16, effect: u16) -> (Spread, usize) {
    let mut pending: Option<Duration> = None;
    let mut samples = Vec::new();
    let mut missed = 0;
    for (t, f) in frames {
        match f.standard_id() {
            Some(id) if id == cause => {
                if pending.is_some() {
                    missed += 1;
                }
                pending = Some(*t);
            }
            Some(id) if id == effect => {
                if let Some(c) = pending.take() {
                    samples.push(t.saturating_sub(c).as_secs_f64() * 1e6);
                }
            }
            _ => {}
        }
    }
    if pending.is_some() {
        missed += 1;
    }
    (Spread::of(samples), missed)
}

/// Cycle of a message: the intervals between consecutive frames (µs) and their deviation from
/// `nominal` (|interval − nominal|, µs).
pub fn cycle_jitter(
    frames: &[(Duration, CanFrame)],
    id: u16,
    nominal: Duration,
) -> (Spread, Spread) {
    let ts: Vec<Duration> = frames
        .iter()
        .filter(|(_, f)| f.standard_id() == Some(id))
        .map(|(t, _)| *t)
        .collect();
    let iv: Vec<f64> = ts
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]).as_secs_f64() * 1e6)
        .collect();
    let nom = nominal.as_secs_f64() * 1e6;
    let dev = iv.iter().map(|v| (v - nom).abs()).collect();
    (Spread::of(iv), Spread::of(dev))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(id: u16) -> CanFrame {
        CanFrame::standard(id, &[0; 8]).unwrap()
    }

    #[test]
    fn latency_pairs_each_cause_with_its_effect() {
        let us = Duration::from_micros;
        let frames = vec![
            (us(0), f(ids::DCT_SENSORS)),
            (us(300), f(ids::TCU_CLUTCH_CMD)),
            (us(10_000), f(ids::DCT_SENSORS)),
            (us(20_000), f(ids::DCT_SENSORS)),
            (us(20_500), f(ids::TCU_CLUTCH_CMD)),
            (us(20_600), f(ids::TCU_CLUTCH_CMD)),
        ];
        let (s, missed) = latency(&frames, ids::DCT_SENSORS, ids::TCU_CLUTCH_CMD);
        assert_eq!((s.n, missed), (2, 1));
        assert_eq!((s.p50_us, s.max_us), (300.0, 500.0));
        let (iv, dev) = cycle_jitter(&frames, ids::DCT_SENSORS, Duration::from_millis(10));
        assert_eq!((iv.n, iv.max_us, dev.max_us), (2, 10_000.0, 0.0));
    }
}

//! Analysis of a recorded bus (a candump log or the frames of a run): the rows the metrics need
//! (one per TCU_Status frame, i.e. per TCU cycle, with the latest value of every message), the
//! latency from a DCT_Sensors frame to the TCU_ClutchCmd frame it causes, and the cycle jitter of
//! a message — all from the recorder's receive timestamps (the kernel's on SocketCAN). The
//! physics can instead be read on bus time ([`on_bus_time`]): the plant's simulated time, one
//! DCT_Sensors frame per cycle, which a host that stalls the daemons or the recorder does not move.

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

/// The clock on which an analysis reads a recording's physics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeAxis {
    /// The plant's simulated time: the n-th DCT_Sensors frame (from 0) is at n cycles of the
    /// DBC's cycle time ([`on_bus_time`]).
    #[default]
    Bus,
    /// The recorder's receive timestamps.
    Receive,
}

/// The recording on bus time: every frame at the time of the plant's latest DCT_Sensors frame
/// (the n-th, from 0, at n · the message's cycle time; frames before the first at 0), in the
/// recorded order. One sensor frame per plant cycle is the plant's contract (a free-running plant
/// sends the cycles a stall made it miss late, not never), so this is the plant's simulated time
/// whatever the host did to the daemons' or the recorder's timing — as long as the recording
/// lost no frame (a log with input loss says so when decoded).
pub fn on_bus_time(frames: &[(Duration, CanFrame)]) -> Vec<(Duration, CanFrame)> {
    let cycle = Duration::from_millis(u64::from(crate::can::messages::DctSensors::CYCLE_MS));
    let mut seen: u32 = 0;
    frames
        .iter()
        .map(|(_, f)| {
            if f.standard_id() == Some(ids::DCT_SENSORS) {
                seen += 1;
            }
            (cycle * seen.saturating_sub(1), *f)
        })
        .collect()
}

/// The recording on `axis` (a copy on bus time, the recording itself on receive time).
pub(crate) fn on_axis(
    frames: &[(Duration, CanFrame)],
    axis: TimeAxis,
) -> std::borrow::Cow<'_, [(Duration, CanFrame)]> {
    match axis {
        TimeAxis::Bus => std::borrow::Cow::Owned(on_bus_time(frames)),
        TimeAxis::Receive => std::borrow::Cow::Borrowed(frames),
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
pub(crate) fn cycle_jitter(
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

    /// A stall of 45 ms between the second and third sensor frames (the host held the plant and
    /// the recorder) moves nothing on bus time: frames sit at 0, 10, 20 ms by the sensor count.
    #[test]
    fn bus_time_counts_sensor_frames_not_receive_stamps() {
        let ms = Duration::from_millis;
        let frames = vec![
            (ms(3), f(ids::TCU_STATUS)),
            (ms(5), f(ids::DCT_SENSORS)),
            (ms(6), f(ids::TCU_CLUTCH_CMD)),
            (ms(15), f(ids::DCT_SENSORS)),
            (ms(60), f(ids::DCT_SENSORS)),
            (ms(61), f(ids::TCU_STATUS)),
        ];
        let t: Vec<u64> = on_bus_time(&frames)
            .iter()
            .map(|(t, _)| t.as_millis() as u64)
            .collect();
        assert_eq!(t, [0, 0, 0, 10, 20, 20]);
        assert_eq!(
            on_axis(&frames, TimeAxis::Receive).as_ref(),
            frames.as_slice()
        );
    }
}

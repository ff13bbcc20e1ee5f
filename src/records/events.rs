//! Event segmentation of a bench record (DESIGN.md §6 step 1): engagements (a clutch transmits
//! torque while slipping), locked phases (it transmits torque without slip) and open phases (both
//! clutches open; the long ones are the cooling phases of Sect. 4.2), from measured signals only.
//!
//! A clutch is "closed" while |T_c| exceeds `torque_on` (with hysteresis down to `torque_off`);
//! closed intervals closer than `merge_s` are merged. The record is also cut into contiguous
//! blocks, each holding one engagement with the open time around it (open stretches longer than
//! `block_open_s` become blocks of their own), for splitting and the event bootstrap.

#![allow(clippy::needless_range_loop)]

/// Segmentation thresholds.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SegmentOptions {
    /// A clutch closes above this torque magnitude (N·m).
    pub torque_on: f64,
    /// …and opens again below this one (N·m).
    pub torque_off: f64,
    /// Closed intervals separated by less than this are one event (s).
    pub merge_s: f64,
    /// Shortest engagement kept (s).
    pub min_engagement_s: f64,
    /// Slip below which a closed clutch counts as locked (rad/s).
    pub lock_slip: f64,
    /// Shortest open phase reported (s).
    pub min_open_s: f64,
    /// Open phases at least this long are cooling phases (s).
    pub cooling_s: f64,
    /// Open stretches longer than this become blocks of their own, cut into pieces of this length.
    pub block_open_s: f64,
}

impl Default for SegmentOptions {
    fn default() -> Self {
        SegmentOptions {
            torque_on: 3.0,
            torque_off: 1.5,
            merge_s: 0.2,
            min_engagement_s: 0.1,
            lock_slip: 0.5,
            min_open_s: 2.0,
            cooling_s: 60.0,
            block_open_s: 30.0,
        }
    }
}

/// Kind of an event.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// A clutch closed and slipping (at least partly).
    Engagement,
    /// A clutch closed without slip.
    Locked,
    /// Both clutches open.
    Open,
    /// Both clutches open for at least `cooling_s`.
    Cooling,
}

/// One event: samples `start..end` of the record.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Event {
    pub kind: EventKind,
    /// 0 or 1 for clutch events, `None` for open phases.
    pub clutch: Option<usize>,
    pub start: usize,
    pub end: usize,
    /// Largest |T_c| in the event (N·m).
    pub peak_torque: f64,
    /// Mean of the measured plate/central-disk temperatures at the start (°C).
    pub theta_start: f64,
}

impl Event {
    pub fn len(&self) -> usize {
        self.end - self.start
    }
    pub fn is_empty(&self) -> bool {
        self.end <= self.start
    }
}

/// Events and blocks of a record.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Segmentation {
    /// Events in time order (clutch events of both clutches and open phases).
    pub events: Vec<Event>,
    /// Contiguous blocks covering the whole record: `(start, end)`.
    pub blocks: Vec<(usize, usize)>,
    /// Closed flag per clutch and sample.
    pub closed: [Vec<bool>; 2],
}

impl Segmentation {
    /// Engagements of one clutch.
    pub fn engagements(&self, clutch: usize) -> impl Iterator<Item = &Event> {
        self.events
            .iter()
            .filter(move |e| e.kind == EventKind::Engagement && e.clutch == Some(clutch))
    }

    /// Index of the block holding sample `k`.
    pub fn block_of(&self, k: usize) -> usize {
        self.blocks
            .partition_point(|&(_, end)| end <= k)
            .min(self.blocks.len().saturating_sub(1))
    }
}

fn closed_flags(t: &[f64], o: &SegmentOptions, dt: f64) -> Vec<bool> {
    let mut c = vec![false; t.len()];
    let mut state = false;
    for (k, v) in t.iter().enumerate() {
        let a = v.abs();
        state = if state {
            a > o.torque_off
        } else {
            a > o.torque_on
        };
        c[k] = state;
    }
    // Merge short gaps.
    let gap = (o.merge_s / dt).round() as usize;
    let mut k = 0;
    while k < c.len() {
        if !c[k] {
            let s = k;
            while k < c.len() && !c[k] {
                k += 1;
            }
            if s > 0 && k < c.len() && k - s <= gap {
                c[s..k].iter_mut().for_each(|v| *v = true);
            }
        } else {
            k += 1;
        }
    }
    c
}

fn runs(flags: &[bool], value: bool) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut k = 0;
    while k < flags.len() {
        if flags[k] == value {
            let s = k;
            while k < flags.len() && flags[k] == value {
                k += 1;
            }
            out.push((s, k));
        } else {
            k += 1;
        }
    }
    out
}

/// The series of a record that segmentation reads (`Dataset::segment_series`): the sample
/// time, each clutch's measured torque and slip, the pressure-plate and central-disk
/// temperatures.
#[derive(Debug, Clone)]
pub struct SegmentSeries<'a> {
    pub dt: f64,
    pub torque: [&'a [f64]; 2],
    pub slip: [Vec<f64>; 2],
    pub pp: [&'a [f64]; 2],
    pub cd: &'a [f64],
}

impl SegmentSeries<'_> {
    fn len(&self) -> usize {
        self.cd.len()
    }
}

/// Segments a record into events and blocks.
pub fn segment(d: &SegmentSeries<'_>, o: &SegmentOptions) -> Segmentation {
    let n = d.len();
    let dt = d.dt;
    let closed = [
        closed_flags(d.torque[0], o, dt),
        closed_flags(d.torque[1], o, dt),
    ];
    let mut events = Vec::new();
    for i in 0..2 {
        events.extend(clutch_events(d, i, &closed[i], o));
    }
    let any_closed: Vec<bool> = (0..n).map(|k| closed[0][k] || closed[1][k]).collect();
    events.extend(open_events(d, &any_closed, o));
    events.sort_by_key(|e| (e.start, e.end));
    let blocks = blocks(&any_closed, o, dt);
    Segmentation {
        events,
        blocks,
        closed,
    }
}

/// The mean of the three measured temperatures at sample `k`.
fn theta_mean(d: &SegmentSeries<'_>, k: usize) -> f64 {
    (d.pp[0][k] + d.pp[1][k] + d.cd[k]) / 3.0
}

/// Clutch `i`'s events: each closed interval long enough, split into slipping (engagement)
/// and locked pieces, with its peak torque and its start temperature.
fn clutch_events(
    d: &SegmentSeries<'_>,
    i: usize,
    closed: &[bool],
    o: &SegmentOptions,
) -> Vec<Event> {
    let min_eng = (o.min_engagement_s / d.dt).round() as usize;
    let slip = &d.slip[i];
    let tq = d.torque[i];
    let mut events = Vec::new();
    for (s, e) in runs(closed, true) {
        if e - s < min_eng.max(1) {
            continue;
        }
        let locked: Vec<bool> = (s..e).map(|k| slip[k].abs() < o.lock_slip).collect();
        for (kind, a, b) in engagement_pieces(&locked, s, e, min_eng) {
            let peak = tq[a..b].iter().fold(0.0f64, |m, v| m.max(v.abs()));
            events.push(Event {
                kind,
                clutch: Some(i),
                start: a,
                end: b,
                peak_torque: peak,
                theta_start: theta_mean(d, a),
            });
        }
    }
    events
}

/// The closed interval `[s, e)` split into slipping and locked pieces, `locked` flagging its
/// samples; short locked blips (under `min_eng` samples) stay in the engagement.
fn engagement_pieces(
    locked: &[bool],
    s: usize,
    e: usize,
    min_eng: usize,
) -> Vec<(EventKind, usize, usize)> {
    let mut pieces: Vec<(bool, usize, usize)> = Vec::new();
    for (a, b) in runs(locked, true) {
        if b - a >= min_eng.max(1) {
            pieces.push((true, s + a, s + b));
        }
    }
    let mut cursor = s;
    let mut out = Vec::new();
    for (_, a, b) in &pieces {
        if *a > cursor {
            out.push((EventKind::Engagement, cursor, *a));
        }
        out.push((EventKind::Locked, *a, *b));
        cursor = *b;
    }
    if cursor < e {
        out.push((EventKind::Engagement, cursor, e));
    }
    out
}

/// The open stretches (both clutches open) long enough: cooling when long, else open.
fn open_events(d: &SegmentSeries<'_>, any_closed: &[bool], o: &SegmentOptions) -> Vec<Event> {
    let min_open = (o.min_open_s / d.dt).round() as usize;
    let cooling = (o.cooling_s / d.dt).round() as usize;
    let mut events = Vec::new();
    for (s, e) in runs(any_closed, false) {
        if e - s >= min_open {
            events.push(Event {
                kind: if e - s >= cooling {
                    EventKind::Cooling
                } else {
                    EventKind::Open
                },
                clutch: None,
                start: s,
                end: e,
                peak_torque: 0.0,
                theta_start: theta_mean(d, s),
            });
        }
    }
    events
}

/// Blocks: cut at the middle of each open stretch between closed intervals; long open stretches
/// are blocks of their own, in pieces of `block_open_s`.
fn blocks(any_closed: &[bool], o: &SegmentOptions, dt: f64) -> Vec<(usize, usize)> {
    let n = any_closed.len();
    let mut cuts = vec![0usize];
    let long = (o.block_open_s / dt).round().max(1.0) as usize;
    let open_runs = runs(any_closed, false);
    for (s, e) in open_runs {
        if s == 0 && e == n {
            break;
        }
        if e - s > 2 * long {
            let (a, b) = (
                if s == 0 { 0 } else { s + long / 4 },
                if e == n { n } else { e - long / 4 },
            );
            let mut k = a;
            while k < b {
                cuts.push(k);
                k += long;
            }
            cuts.push(b);
        } else if s > 0 && e < n {
            cuts.push((s + e) / 2);
        }
    }
    if n > 0 && (!any_closed.iter().any(|c| *c)) {
        let mut k = long;
        while k < n {
            cuts.push(k);
            k += long;
        }
    }
    cuts.push(n);
    cuts.sort_unstable();
    cuts.dedup();
    cuts.windows(2)
        .filter(|w| w[1] > w[0])
        .map(|w| (w[0], w[1]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record of clutch 1's torque `torque1` at the slip `slip` (clutch 2 open, 30 °C).
    struct Record {
        torque: [Vec<f64>; 2],
        slip: [Vec<f64>; 2],
        theta: Vec<f64>,
    }

    impl Record {
        fn len(&self) -> usize {
            self.theta.len()
        }

        fn series(&self) -> SegmentSeries<'_> {
            SegmentSeries {
                dt: 0.01,
                torque: [&self.torque[0], &self.torque[1]],
                slip: self.slip.clone(),
                pp: [&self.theta, &self.theta],
                cd: &self.theta,
            }
        }
    }

    fn record(torque1: Vec<f64>, slip: f64) -> Record {
        let n = torque1.len();
        Record {
            torque: [torque1, vec![0.0; n]],
            slip: [vec![slip; n], vec![0.0; n]],
            theta: vec![30.0; n],
        }
    }

    #[test]
    fn engagements_open_phases_and_blocks() {
        // Three 1 s engagements every 10 s, then 100 s open.
        let mut t = Vec::new();
        for _ in 0..3 {
            t.extend(vec![0.0; 450]);
            t.extend(vec![50.0; 100]);
            t.extend(vec![0.0; 450]);
        }
        t.extend(vec![0.0; 10_000]);
        let d = record(t, 100.0);
        let s = segment(&d.series(), &SegmentOptions::default());
        let eng: Vec<_> = s.engagements(0).collect();
        assert_eq!(eng.len(), 3);
        assert_eq!((eng[0].start, eng[0].end), (450, 550));
        assert_eq!(eng[1].peak_torque, 50.0);
        assert_eq!(s.engagements(1).count(), 0);
        let cooling: Vec<_> = s
            .events
            .iter()
            .filter(|e| e.kind == EventKind::Cooling)
            .collect();
        assert_eq!(cooling.len(), 1);
        assert_eq!(cooling[0].start, 2550);
        // Blocks cover the record without overlap, each engagement in its own block.
        assert_eq!(s.blocks[0].0, 0);
        assert_eq!(s.blocks.last().unwrap().1, d.len());
        for w in s.blocks.windows(2) {
            assert_eq!(w[0].1, w[1].0);
        }
        let b: Vec<usize> = eng.iter().map(|e| s.block_of(e.start)).collect();
        assert!(b[0] < b[1] && b[1] < b[2]);
        assert!(s.blocks.len() >= 3 + 10_000 / 3000);
    }

    #[test]
    fn locked_phase_is_split_and_noise_ignored() {
        let mut t = vec![0.0; 100];
        t.extend(vec![1.0; 50]); // below the threshold: not an engagement
        t.extend(vec![0.0; 100]);
        t.extend(vec![40.0; 200]);
        t.extend(vec![0.0; 100]);
        let mut d = record(t, 50.0);
        // Locked (zero slip) for the second half of the engagement.
        d.slip[0][350..450].iter_mut().for_each(|v| *v = 0.0);
        let s = segment(&d.series(), &SegmentOptions::default());
        let c: Vec<_> = s.events.iter().filter(|e| e.clutch == Some(0)).collect();
        assert_eq!(c.len(), 2);
        assert_eq!(
            (c[0].kind, c[0].start, c[0].end),
            (EventKind::Engagement, 250, 350)
        );
        assert_eq!(
            (c[1].kind, c[1].start, c[1].end),
            (EventKind::Locked, 350, 450)
        );
    }
}

//! One open launch or shift of the metrics' stream: its figures accumulated row by row from the
//! row that starts it, in the row order of the slice computation (so every fold and sum takes
//! the same values in the same order and gives the same bits), without keeping the rows.
//!
//! How far an event looks, and so how long it stays open:
//! - **backward**: 100 ms before its start (shift: mean acceleration before) or before the
//!   lock-up (launch: mean acceleration before lock-up, which may reach back before the start).
//!   Those windows are read from the stream's ring of recent rows (`RECENT_S`) when the
//!   start or the lock-up row arrives.
//! - **forward**: a launch runs until the launch clutch locks (|slip| < 5 rpm) or the TCU leaves
//!   Launch/Drive, then 50 rows more (lowest engine speed), 300 ms after the lock-up (spike) and
//!   at least 600 ms after the start (peak acceleration); a shift until the TCU leaves its state,
//!   then 200 ms more (lowest acceleration). The searches for the lock-up and the end of the
//!   shift are unbounded in principle (a scenario can hold Launch/Drive or a shift state to its
//!   end), but they only fold running figures, so an event holds O(1) memory however long it
//!   stays open. At most one launch is searching at a time (the next launch starts from
//!   Creep/Neutral/Init, which ends the search) and likewise one shift; the others only wait out
//!   their bounded tails.

use super::figures::{LaunchMetrics, ShiftMetrics, SlipBin, RPM, SLIP_BINS_RADPS};
use crate::can::messages::TcuState;
use crate::model::gear::Gear;
use crate::sim::row::Row;
use std::collections::VecDeque;

/// Rows after the end of the engagement still counted in a launch's lowest engine speed.
const LAUNCH_TAIL_ROWS: usize = 50;

/// The neutral element of `Iterator::sum` for `f64` (−0.0 in current std, 0.0 before): a running
/// sum started from it equals the iterator's sum of the same values in the same order.
fn sum_zero() -> f64 {
    std::iter::empty::<f64>().sum()
}

/// Mean acceleration of the `recent` rows in [a, b), as the slice computation's windows.
fn mean_accel(recent: &VecDeque<Row>, a: f64, b: f64) -> Option<f64> {
    let v: Vec<f64> = recent
        .iter()
        .filter(|r| r.t_s >= a && r.t_s < b)
        .map(|r| r.accel_mps2)
        .collect();
    if v.is_empty() {
        None
    } else {
        Some(v.iter().sum::<f64>() / v.len() as f64)
    }
}

/// Running sums of one slip bin.
#[derive(Debug, Clone, Copy)]
struct BinSums {
    err: f64,
    rel: f64,
    n: usize,
}

impl BinSums {
    fn new() -> Self {
        Self {
            err: sum_zero(),
            rel: sum_zero(),
            n: 0,
        }
    }
}

/// The launch figures fixed at its first row.
#[derive(Debug, Clone, Copy)]
pub(super) struct LaunchStart {
    pub t0: f64,
    pub pedal_pct: f64,
    pub target_rpm: f64,
    /// The launch clutch (0 odd, 1 even).
    pub clutch: usize,
    pub idle_rpm: f64,
}

/// An open launch.
#[derive(Debug, Clone)]
pub(super) struct Launch {
    start: LaunchStart,
    /// Still in the engagement (searching for lock-up or the end of Launch/Drive).
    engaging: bool,
    /// The previous row of the engagement (friction energy over consecutive pairs).
    last_seg: Option<Row>,
    tail_left: usize,
    t_lock: Option<f64>,
    t_last: f64,
    min_e: f64,
    max_e: f64,
    pre: Option<f64>,
    post: f64,
    peak_err: f64,
    peak_acc: f64,
    bins: [BinSums; SLIP_BINS_RADPS.len() - 1],
    energy: f64,
}

impl Launch {
    pub fn new(start: LaunchStart) -> Self {
        Self {
            start,
            engaging: true,
            last_seg: None,
            tail_left: 0,
            t_lock: None,
            t_last: start.t0,
            min_e: f64::INFINITY,
            max_e: 0.0,
            pre: None,
            post: f64::MIN,
            peak_err: 0.0,
            peak_acc: f64::MIN,
            bins: [BinSums::new(); SLIP_BINS_RADPS.len() - 1],
            energy: 0.0,
        }
    }

    /// The next row (the first is the launch's own), with the rows before it in `recent`.
    pub fn push(&mut self, r: &Row, recent: &VecDeque<Row>) {
        let (t0, c) = (self.start.t0, self.start.clutch);
        if r.t_s >= t0 && r.t_s < t0 + 0.3 {
            self.peak_err = self.peak_err.max((r.t_ref_nm[c] - r.t_act_nm[c]).abs());
        }
        if r.t_s >= t0 && r.t_s < t0 + 0.6 {
            self.peak_acc = self.peak_acc.max(r.accel_mps2);
        }
        if self.engaging {
            self.engage(r, recent);
        } else if self.tail_left > 0 {
            self.tail(r);
        }
        if let Some(tl) = self.t_lock {
            if r.t_s >= tl && r.t_s < tl + 0.3 {
                self.post = self.post.max(r.accel_mps2);
            }
        }
        self.t_last = r.t_s;
    }

    /// A row while engaging: it ends the engagement (leaving Launch/Drive), locks up, or is one
    /// more row of it.
    fn engage(&mut self, r: &Row, recent: &VecDeque<Row>) {
        let c = self.start.clutch;
        if !matches!(r.state, TcuState::Launch | TcuState::Drive) {
            self.end_engagement(r);
        } else if r.slip_rpm(c).abs() < 5.0 {
            self.t_lock = Some(r.t_s);
            self.pre = mean_accel(recent, r.t_s - 0.1, r.t_s);
            if self.last_seg.is_none() {
                // Locked at its first row: the engagement is that row alone.
                self.add_seg(r);
                self.engaging = false;
                self.tail_left = LAUNCH_TAIL_ROWS;
            } else {
                self.end_engagement(r);
            }
        } else {
            self.add_seg(r);
        }
    }

    /// The engagement ends before `r`, which is the first row of the tail.
    fn end_engagement(&mut self, r: &Row) {
        self.engaging = false;
        self.tail_left = LAUNCH_TAIL_ROWS;
        self.tail(r);
    }

    fn tail(&mut self, r: &Row) {
        self.min_e = self.min_e.min(r.n_e_rpm);
        self.tail_left -= 1;
    }

    /// One row of the engagement: engine speeds, slip bins and friction energy.
    fn add_seg(&mut self, r: &Row) {
        let c = self.start.clutch;
        self.min_e = self.min_e.min(r.n_e_rpm);
        self.max_e = self.max_e.max(r.n_e_rpm);
        let s = r.slip_rpm(c).abs() * RPM;
        for (b, w) in self.bins.iter_mut().zip(SLIP_BINS_RADPS.windows(2)) {
            if s < w[0] && s >= w[1] && r.t_ref_nm[c] > 1.0 {
                b.err += r.t_ref_nm[c] - r.t_act_nm[c];
                b.rel += (r.t_ref_nm[c] - r.t_act_nm[c]) / r.t_ref_nm[c];
                b.n += 1;
            }
        }
        if let Some(p) = &self.last_seg {
            let dt = r.t_s - p.t_s;
            self.energy += p.t_act_nm[c] * p.slip_rpm(c) * RPM * dt;
        }
        self.last_seg = Some(*r);
    }

    /// No later row can change a figure.
    pub fn done(&self) -> bool {
        !self.engaging
            && self.tail_left == 0
            && self.t_lock.is_none_or(|tl| self.t_last >= tl + 0.3)
            && self.t_last >= self.start.t0 + 0.6
    }

    pub fn finish(self) -> LaunchMetrics {
        let s = self.start;
        let mean = |sum: f64, n: usize| (n > 0).then(|| sum / n as f64);
        let bins = self
            .bins
            .iter()
            .zip(SLIP_BINS_RADPS.windows(2))
            .map(|(b, w)| SlipBin {
                slip_hi_radps: w[0],
                slip_lo_radps: w[1],
                mean_error_nm: mean(b.err, b.n),
                mean_rel_error: mean(b.rel, b.n),
                n: b.n,
            })
            .collect();
        LaunchMetrics {
            t_start_s: s.t0,
            pedal_pct: s.pedal_pct,
            target_rpm: s.target_rpm,
            lockup_s: self.t_lock.map(|t| t - s.t0),
            stall: self.min_e < 0.6 * s.idle_rpm,
            min_engine_rpm: self.min_e,
            max_engine_rpm: self.max_e,
            flare_rpm: self.max_e - s.target_rpm,
            accel_before_lockup_mps2: self.pre,
            lockup_spike_mps2: self.pre.map(|a| self.post - a),
            peak_torque_error_300ms_nm: self.peak_err,
            peak_accel_600ms_mps2: self.peak_acc,
            torque_error_by_slip: bins,
            friction_energy_kj: self.energy / 1e3,
        }
    }
}

/// How a shift ended: time, gear then, whether in Drive.
#[derive(Debug, Clone, Copy)]
struct ShiftEnd {
    t_s: f64,
    to: Gear,
    completed: bool,
}

/// An open shift.
#[derive(Debug, Clone)]
pub(super) struct Shift {
    t0: f64,
    state: TcuState,
    from: Gear,
    accel_before: f64,
    end: Option<ShiftEnd>,
    /// The latest row's time and gear (the end when the run ends first).
    last: (f64, Gear),
    min_acc: f64,
    max_e: f64,
    done: bool,
}

impl Shift {
    /// A shift starting at `r` (after `prev`), with the rows before `r` in `recent`.
    pub fn new(r: &Row, prev: &Row, recent: &VecDeque<Row>) -> Self {
        Self {
            t0: r.t_s,
            state: r.state,
            from: prev.gear_active,
            accel_before: mean_accel(recent, r.t_s - 0.1, r.t_s).unwrap_or(0.0),
            end: None,
            last: (r.t_s, r.gear_active),
            min_acc: f64::INFINITY,
            max_e: 0.0,
            done: false,
        }
    }

    /// The next row (the first is the shift's own).
    pub fn push(&mut self, r: &Row) {
        if self.end.is_none() {
            self.max_e = self.max_e.max(r.n_e_rpm);
            if r.state != self.state {
                self.end = Some(ShiftEnd {
                    t_s: r.t_s,
                    to: r.gear_active,
                    completed: r.state == TcuState::Drive,
                });
            }
        }
        // Until the end is known every row lies before it.
        let t_upto = self.end.map_or(f64::INFINITY, |e| e.t_s + 0.2);
        if r.t_s >= self.t0 && r.t_s <= t_upto {
            self.min_acc = self.min_acc.min(r.accel_mps2);
        } else if r.t_s > t_upto {
            self.done = true;
        }
        self.last = (r.t_s, r.gear_active);
    }

    /// No later row can change a figure.
    pub fn done(&self) -> bool {
        self.done
    }

    pub fn finish(self) -> ShiftMetrics {
        let end = self.end.unwrap_or(ShiftEnd {
            t_s: self.last.0,
            to: self.last.1,
            completed: false,
        });
        ShiftMetrics {
            t_start_s: self.t0,
            up: self.state == TcuState::Upshift,
            from: self.from,
            to: end.to,
            duration_s: end.t_s - self.t0,
            completed: end.completed,
            min_accel_mps2: self.min_acc,
            accel_before_mps2: self.accel_before,
            max_engine_rpm: self.max_e,
        }
    }
}

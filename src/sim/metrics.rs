//! Acceptance metrics from the rows of a run — everything from what the bus carried (the TCU's
//! TCU_Status/TCU_Estimates, the plant's sensor, bench and truth frames), so the same definitions
//! apply to a log recorded on a real bus.
//!
//! - **Launch** (TcuState enters Launch from Creep/Neutral): lock-up time (first row after the
//!   start with |slip| of the launch clutch below 5 rpm), stall (engine below 60 % of idle), flare
//!   (highest engine speed before lock-up minus the launch target n(p) of the calibration),
//!   lock-up spike (largest vehicle acceleration in the 300 ms from lock-up minus the mean over the
//!   100 ms before it), the peak |T_ref − T_actual| of the launch clutch in the first 300 ms, the
//!   peak vehicle acceleration in the first 600 ms, and the mean torque error T_ref − T_actual
//!   binned by slip over the engagement (the paper's Fig. 14).
//! - **Shift** (TcuState Upshift/Downshift until Drive): gears, duration, lowest vehicle
//!   acceleration from the start to 200 ms after the end.
//! - **Estimator**: RMSE and largest error of the estimated clutch temperatures (TCU_Estimates)
//!   against SIM_Truth over the run.

use super::row::Row;
use crate::can::messages::TcuState;
use crate::tcu::TcuConfig;
use std::collections::VecDeque;

mod events;
mod figures;
#[cfg(test)]
pub(super) mod reference;

use figures::launch_clutch;
pub use figures::{
    EstimatorMetrics, LaunchMetrics, Metrics, ShiftMetrics, SlipBin, StatusEvent, SLIP_BINS_RADPS,
};

/// Metrics of a run's rows (the rows streamed through [`Stream`]).
pub fn compute(rows: &[Row], cfg: &TcuConfig) -> Metrics {
    let mut s = Stream::new(cfg);
    for r in rows {
        s.push(r);
    }
    s.finish()
}

/// How far back the stream keeps rows: the windows before a launch's lock-up and before a
/// shift's start reach 100 ms back; the rest is margin (a row is dropped only when it is more
/// than this older than the newest).
const RECENT_S: f64 = 0.2;

/// The metrics of a run computed row by row as the rows come: the same [`Metrics`] as
/// [`compute`] on all of them, bit for bit, holding only the rows of the last [`RECENT_S`], the
/// open launches and shifts (their running figures, see `events`) and running sums — memory
/// independent of the run's length.
#[derive(Debug, Clone)]
pub struct Stream {
    idle_rpm: f64,
    launch_rpm: [f64; 2],
    /// The latest rows (the last is the previous row), in time order.
    recent: VecDeque<Row>,
    open_launches: VecDeque<events::Launch>,
    open_shifts: VecDeque<events::Shift>,
    launches: Vec<LaunchMetrics>,
    shifts: Vec<ShiftMetrics>,
    estimator: EstimatorSums,
    status_events: Vec<StatusEvent>,
    max_speed_kmh: f64,
    min_engine_rpm_driving: f64,
    nonfinite: bool,
}

impl Stream {
    /// An empty stream; `cfg` gives the launch targets n(p) and the idle speed (stall).
    pub fn new(cfg: &TcuConfig) -> Self {
        Self {
            idle_rpm: cfg.physics.engine.idle_speed_rpm,
            launch_rpm: [cfg.launch.engine_rpm_0, cfg.launch.engine_rpm_100],
            recent: VecDeque::new(),
            open_launches: VecDeque::new(),
            open_shifts: VecDeque::new(),
            launches: Vec::new(),
            shifts: Vec::new(),
            estimator: EstimatorSums::new(),
            status_events: Vec::new(),
            max_speed_kmh: 0.0,
            min_engine_rpm_driving: f64::INFINITY,
            nonfinite: false,
        }
    }

    /// The next row (rows in time order).
    pub fn push(&mut self, r: &Row) {
        self.open_events(r);
        for l in &mut self.open_launches {
            l.push(r, &self.recent);
        }
        for s in &mut self.open_shifts {
            s.push(r);
        }
        self.close_events();
        self.run_figures(r);
        self.recent.push_back(*r);
        while self
            .recent
            .front()
            .is_some_and(|f| f.t_s < r.t_s - RECENT_S)
        {
            self.recent.pop_front();
        }
    }

    /// A launch or shift starting at `r`.
    fn open_events(&mut self, r: &Row) {
        let Some(prev) = self.recent.back() else {
            return;
        };
        if r.state == TcuState::Launch
            && matches!(
                prev.state,
                TcuState::Creep | TcuState::Neutral | TcuState::Init
            )
        {
            let [rpm_0, rpm_100] = self.launch_rpm;
            let p = r.pedal_pct / 100.0;
            self.open_launches
                .push_back(events::Launch::new(events::LaunchStart {
                    t0: r.t_s,
                    pedal_pct: r.pedal_pct,
                    target_rpm: rpm_0 + (rpm_100 - rpm_0) * p,
                    clutch: launch_clutch(r),
                    idle_rpm: self.idle_rpm,
                }));
        }
        if matches!(r.state, TcuState::Upshift | TcuState::Downshift) && prev.state != r.state {
            self.open_shifts
                .push_back(events::Shift::new(r, prev, &self.recent));
        }
    }

    /// Finishes the events no later row can change, in start order.
    fn close_events(&mut self) {
        while self.open_launches.front().is_some_and(events::Launch::done) {
            if let Some(l) = self.open_launches.pop_front() {
                self.launches.push(l.finish());
            }
        }
        while self.open_shifts.front().is_some_and(events::Shift::done) {
            if let Some(s) = self.open_shifts.pop_front() {
                self.shifts.push(s.finish());
            }
        }
    }

    /// The figures over the whole run: estimator errors, status changes, extremes, finiteness.
    fn run_figures(&mut self, r: &Row) {
        self.estimator.push(r);
        if self
            .recent
            .back()
            .is_none_or(|p| r.state != p.state || r.fault != p.fault)
        {
            self.status_events.push(StatusEvent {
                t_s: r.t_s,
                state: r.state,
                fault: r.fault,
            });
        }
        self.nonfinite |= nonfinite(r);
        self.max_speed_kmh = self.max_speed_kmh.max(r.v_kmh);
        if matches!(
            r.state,
            TcuState::Launch | TcuState::Drive | TcuState::Upshift | TcuState::Downshift
        ) {
            self.min_engine_rpm_driving = self.min_engine_rpm_driving.min(r.n_e_rpm);
        }
    }

    /// The metrics of all rows pushed (events still open end with the run).
    pub fn finish(mut self) -> Metrics {
        self.launches
            .extend(self.open_launches.drain(..).map(events::Launch::finish));
        self.shifts
            .extend(self.open_shifts.drain(..).map(events::Shift::finish));
        Metrics {
            launches: self.launches,
            shifts: self.shifts,
            estimator: self.estimator.finish(),
            status_events: self.status_events,
            max_speed_kmh: self.max_speed_kmh,
            min_engine_rpm_driving: self.min_engine_rpm_driving,
            nonfinite: self.nonfinite,
        }
    }
}

/// Any non-finite value among a row's decoded signals.
fn nonfinite(r: &Row) -> bool {
    [
        r.n_e_rpm,
        r.t_e_nm,
        r.x_ref_mm[0],
        r.x_ref_mm[1],
        r.t_ref_nm[0],
        r.t_ref_nm[1],
        r.theta_est_c[0],
        r.theta_est_c[1],
        r.accel_mps2,
    ]
    .iter()
    .any(|v| !v.is_finite())
        || r.eng_req_nm.is_some_and(|v| !v.is_finite())
}

/// Running sums of the estimator's errors.
#[derive(Debug, Clone, Copy)]
struct EstimatorSums {
    n: usize,
    se: [f64; 2],
    mx: [f64; 2],
    mt: [f64; 2],
}

impl EstimatorSums {
    fn new() -> Self {
        Self {
            n: 0,
            se: [0.0; 2],
            mx: [0.0; 2],
            mt: [f64::MIN; 2],
        }
    }

    fn push(&mut self, r: &Row) {
        // Rows before the first SIM_Truth or the first TCU_Estimates frame (both decode to
        // exactly 0 °C until seen): nothing to compare. On a bus the plant's first cycle can
        // precede the TCU's first estimate now that it starts as soon as the TCU listens.
        let unseen = |t: [f64; 2]| t[0] == 0.0 && t[1] == 0.0;
        if unseen(r.theta_true_c) || unseen(r.theta_est_c) {
            return;
        }
        self.n += 1;
        for i in 0..2 {
            let e = r.theta_est_c[i] - r.theta_true_c[i];
            self.se[i] += e * e;
            self.mx[i] = self.mx[i].max(e.abs());
            self.mt[i] = self.mt[i].max(r.theta_true_c[i]);
        }
    }

    fn finish(self) -> EstimatorMetrics {
        let n = self.n;
        EstimatorMetrics {
            samples: n,
            rmse_c: self
                .se
                .map(|s| if n > 0 { (s / n as f64).sqrt() } else { 0.0 }),
            max_abs_c: self.mx,
            max_true_c: self.mt,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::reference::assert_same;
    use super::*;
    use crate::model::gear::Gear;

    /// A row in `state` and `gear` at `t_s`, with launch-clutch slip `slip_rpm` and otherwise
    /// varying figures.
    fn row(t_s: f64, state: TcuState, gear: Gear, slip_rpm: f64, x: f64) -> Row {
        let n_e = 1500.0 + 400.0 * (3.0 * x).cos();
        let c = usize::from(gear.is_reverse());
        let mut n_c = [900.0; 2];
        n_c[c] = n_e - slip_rpm;
        Row {
            t_s,
            state,
            gear_active: gear,
            pedal_pct: 30.0 + 10.0 * x.sin(),
            n_e_rpm: n_e,
            n_c_rpm: n_c,
            t_ref_nm: [50.0 + 40.0 * (2.0 * x).sin(); 2],
            t_act_nm: [48.0 + 41.0 * (2.0 * x).sin(); 2],
            accel_mps2: 2.0 * (5.0 * x).sin(),
            v_kmh: 30.0 + 20.0 * x.sin(),
            theta_est_c: [60.0 + x, 50.0],
            theta_true_c: [61.0 + x.cos(), 50.5],
            ..Row::default()
        }
    }

    /// Launches and shifts at the edges of their windows: a launch on the second row (its
    /// windows reach before the first), one locked on its first row, a reverse one, one still
    /// engaging at the end; launches 100 ms apart (tails overlapping), an upshift straight into
    /// a downshift, a shift open at the end; on a 10 ms, a 1 ms and an uneven time grid, and
    /// every prefix of the rows (events open when the rows end).
    #[test]
    fn the_stream_matches_the_slice_computation_at_the_window_edges() {
        use Gear::{G1, G2, R};
        use TcuState::{Creep, Downshift, Drive, Init, Launch, Upshift};
        // (state, gear, rows, slip at the last of them; the slip falls 40 rpm a row towards it)
        let script: &[(TcuState, Gear, usize, f64)] = &[
            (Init, G1, 1, 300.0),
            (Launch, G1, 30, 2.0),
            (Drive, G1, 5, 1.0),
            (Upshift, G1, 8, 400.0),
            (Downshift, G2, 6, 400.0),
            (Drive, G1, 3, 0.0),
            (Creep, G1, 4, 300.0),
            (Launch, G1, 1, 1.0),
            (Creep, R, 10, 300.0),
            (Launch, R, 12, 3.0),
            (Creep, G1, 2, 300.0),
            (Launch, G1, 40, 300.0),
            (Upshift, G1, 3, 400.0),
            (Drive, G2, 70, 0.0),
            (Creep, G1, 2, 300.0),
            (Launch, G1, 25, 300.0),
            (Upshift, G1, 4, 400.0),
        ];
        let cfg = TcuConfig::default();
        let grids: [&dyn Fn(usize) -> f64; 3] =
            [&|k| k as f64 * 0.01, &|k| k as f64 * 0.001, &|k| {
                (k as f64 * 0.007) + 0.003 * ((k % 3) as f64)
            }];
        for (g, grid) in grids.iter().enumerate() {
            let rows = script_rows(script, grid);
            let want = reference::compute(&rows, &cfg);
            assert_eq!(
                (want.launches.len(), want.shifts.len()),
                (5, 4),
                "{want:#?}"
            );
            assert_eq!(want.launches[1].lockup_s, Some(0.0));
            assert!(want.launches[2].lockup_s.is_some() && want.launches[3].lockup_s.is_none());
            assert!(
                !want.shifts[0].completed && want.shifts[1].completed && !want.shifts[3].completed
            );
            assert_same(&compute(&rows, &cfg), &want, &format!("grid {g}"));
            for n in 0..rows.len() {
                let want = reference::compute(&rows[..n], &cfg);
                assert_same(
                    &compute(&rows[..n], &cfg),
                    &want,
                    &format!("grid {g}, {n} rows"),
                );
            }
        }
    }

    /// The rows of a script.
    fn script_rows(
        script: &[(TcuState, Gear, usize, f64)],
        grid: &dyn Fn(usize) -> f64,
    ) -> Vec<Row> {
        let mut rows = Vec::new();
        for &(state, gear, n, slip_end) in script {
            for i in 0..n {
                let k = rows.len();
                let slip = slip_end + 40.0 * (n - 1 - i) as f64;
                rows.push(row(grid(k), state, gear, slip, k as f64 / 100.0));
            }
        }
        rows
    }
}

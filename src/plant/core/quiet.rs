//! Multi-rate integration: a quiet bus cycle in one RK4 step (issue 14; the paper's model
//! (13)–(20) is unchanged, only its integration).
//!
//! The stiff parts of the plant are the stick/slip events of the clutches (13) at lock-up and
//! break-away with the cube-root friction near zero slip, the synchronisers, and the road load's
//! regularised friction near standstill; they need the 1 ms step. In between — a clutch locked
//! and carrying its torque, open below its kiss point, or slipping far from lock-up, no gear
//! moving, the requests constant over the cycle (the TCU's commands change only at
//! cycle boundaries, the driver's table is flat) — what moves is smooth and slow (the rigid
//! engine–vehicle body, the engine lag and idle governor, the actuators settling, the thermal
//! network (16)), and one RK4 step of the whole 10 ms cycle follows it closely.
//!
//! A cycle is taken in one step only when, in order:
//! 1. the plant can (vehicle mode, `[plant] step = "multirate"`, no dead-time line, no effect
//!    that needs the outputs every step);
//! 2. the inputs of the cycle's last 1 ms step are those of its first (the latched commands keep
//!    their freshness, [`Scenario::constant_over`](crate::plant::profile::Scenario::constant_over));
//! 3. the one step, tried on a copy, has no event: no lock, break-away, gear engagement, located
//!    slip crossing; the gear shafts unchanged and not synchronising; every clutch either locked
//!    at both ends with its torque within the static capacity at the end, or without capacity at
//!    both ends (the actuator moves monotonically towards a constant request, so it is open in
//!    between too), or slipping far from lock-up at both ends with the same sign and a friction
//!    that is not stiff for the step (`slip_not_stiff`); the road load not stiff for the step, or the vehicle at rest at both ends;
//!    a finite state.
//!
//! Otherwise the cycle is integrated at the 1 ms step, exactly as with `step = "fixed"`. The
//! accuracy against the fixed step is tested on the bench's scenarios in `tests/tcu.rs`: on the
//! same TCU commands (lock-ups, break-aways and gear engagements within one cycle, peak clutch
//! torques within 0.5 %) and in closed loop (the same launches, shifts and verdicts).

use super::{finite, Latched, Plant};
use crate::model::driveline::{load_stiffness, C1, F, OUT};
use crate::model::powertrain::{Hooks, Inputs, Outputs, State, StepReport};
use crate::plant::config::{Mode, StepPolicy};
use std::time::Duration;

/// Largest λ·h of the road load's mode for a step over the cycle: well inside classical RK4's
/// stability interval (λh ≤ 2.79), where its error per step is below 3·10⁻⁴ of the mode.
const MAX_LOAD_STIFFNESS_H: f64 = 0.5;

/// Slip (rad/s) below which a slipping clutch always takes the 1 ms step (lock-up and its
/// cube-root friction near zero slip).
const MIN_SLIP_RADPS: f64 = 20.0;

/// Largest λ·h of a slipping clutch's slip mode for a step over the cycle (as the road load's).
const MAX_SLIP_STIFFNESS_H: f64 = 0.5;

/// Output speed (rad/s) taken as at rest for [`Plant::load_not_stiff`]: a vehicle held by the
/// brake decays towards exactly zero; at the stiffest load (full brake, RK4's amplification of
/// about 40 over a 10 ms step) a cycle that starts below this ends below 4·10⁻⁸ rad/s, and the next
/// cycle that would leave it is taken at 1 ms — ten million times below the speed sensor's
/// resolution (0.5 rpm).
const REST_RADPS: f64 = 1e-9;

impl Plant {
    /// Integrates the bus cycle starting now in one step when it is quiet (see the module
    /// documentation); false, the plant as it was, when it is not.
    pub(super) fn quiet_cycle(&mut self) -> bool {
        if !self.may_skip_substeps() {
            return false;
        }
        let n = self.steps_per_cycle;
        let t0 = self.time();
        let t_last = Duration::from_secs_f64((self.steps + n - 1) as f64 * self.dt);
        // The first step's commands (what the 1 ms steps would form first, so calling it twice
        // when the cycle turns out not to be quiet changes nothing).
        let mut u = self.commands(t0);
        if !self.inputs_constant(t0, t_last) {
            return false;
        }
        u.x1_ref_mm = self.x_ref[0];
        u.x2_ref_mm = self.x_ref[1];
        let h = n as f64 * self.dt;
        let mut s = self.s;
        let rep = self.pt.advance(&mut s, &u, h);
        let end = self.pt.outputs(&s, &u);
        if !self.quiet_step(&u, &s, &rep, &end) {
            return false;
        }
        self.x_ref_applied = self.x_ref;
        self.s = s;
        self.last_finite = s;
        self.u_last = u;
        self.last_out = end;
        self.out_fresh = true;
        self.pt.hooks.advance(&self.s, None, h);
        self.relax_housing(self.housing_decay[1]);
        self.steps += n;
        self.stats.steps += n;
        self.stats.quiet_cycles += 1;
        true
    }

    /// What the plant's set-up allows (item 1 of the module documentation).
    fn may_skip_substeps(&self) -> bool {
        self.cfg.step == StepPolicy::Multirate
            && self.cfg.mode == Mode::Vehicle
            && self.steps_per_cycle > 1
            && self.delay_steps == 0
            && !self.pt.hooks.needs_outputs()
    }

    /// The inputs at `t_last` are those formed at `t0` (item 2).
    fn inputs_constant(&self, t0: Duration, t_last: Duration) -> bool {
        let limit = super::CYCLE * self.cfg.inputs.timeout_cycles;
        let l = &self.latch;
        let driver = match &self.cfg.scenario {
            Some(sc) => match self.sampler.holds(self.steps / self.steps_per_cycle) {
                Some(held) => held,
                None => sc.constant_over(t0.as_secs_f64(), t_last.as_secs_f64()),
            },
            None => keeps_freshness(&l.pedal, t_last, limit),
        };
        driver
            && keeps_freshness(&l.clutch, t_last, limit)
            && keeps_freshness(&l.engine, t_last, limit)
            && keeps_freshness(&l.gear, t_last, limit)
    }

    /// The one step `s` (from `self.s` with the inputs `u`, the outputs `end` at its end) has no
    /// event, every clutch stays locked or open, and the road load is not stiff (item 3).
    fn quiet_step(&self, u: &Inputs, s: &State, rep: &StepReport, end: &Outputs) -> bool {
        let s0 = &self.s;
        let no_event = rep.events == 0
            && rep.locked == [false; 2]
            && rep.unlocked == [false; 2]
            && rep.engaged == [false; 2];
        let gears = s.gear_odd == s0.gear_odd
            && s.gear_even == s0.gear_even
            && !s.gear_odd.syncing()
            && !s.gear_even.syncing();
        let clutch = |i: usize| {
            let cap0 = self
                .pt
                .hooks
                .clutch_capacity(&self.pt.p.clutch, &self.pt.clutch_context(s0, i));
            let (need, cap1) = if i == 0 {
                (end.t_fc1_nm, end.capacity1_nm)
            } else {
                (end.t_fc2_nm, end.capacity2_nm)
            };
            match (s0.locked(i), s.locked(i)) {
                (true, true) => need.abs() <= cap1,
                (false, false) => {
                    (cap0 == 0.0 && cap1 == 0.0)
                        || (self.slip_not_stiff(i, s0) && self.slip_not_stiff(i, s))
                }
                _ => false,
            }
        };
        no_event && gears && clutch(0) && clutch(1) && finite(s) && self.load_not_stiff(u, s)
    }

    /// A slipping clutch whose friction is not stiff for one step over the cycle at state `s`:
    /// far from lock-up (|slip| ≥ [`MIN_SLIP_RADPS`]), where ∂T/∂ω_slip (central difference of
    /// the clutch torque) over the flywheel's and the disk's inertias alone times the step is at
    /// most [`MAX_SLIP_STIFFNESS_H`]. With the same slip sign at both ends (the step's event
    /// locator finds no crossing), the slip stays away from zero in between.
    fn slip_not_stiff(&self, i: usize, s: &State) -> bool {
        let ctx = self.pt.clutch_context(s, i);
        let w = ctx.slip_radps;
        if w.abs() < MIN_SLIP_RADPS || w * self.s.slip(i) <= 0.0 {
            return false;
        }
        let c = &self.pt.p.clutch;
        let d = 1e-3 * w.abs();
        let at = |slip: f64| {
            let mut x = ctx;
            x.slip_radps = slip;
            self.pt.hooks.clutch_torque(c, &x)
        };
        let dtdw = ((at(w + d) - at(w - d)) / (2.0 * d)).abs();
        let j = self.pt.inertias();
        let h = self.steps_per_cycle as f64 * self.dt;
        dtdw * (1.0 / j[F] + 1.0 / j[C1 + i]) * h <= MAX_SLIP_STIFFNESS_H
    }

    /// The road load is not stiff for one step over the cycle: at both ends (on the same side of
    /// standstill, the stiffness falling monotonically with the speed) the load's stiffness over
    /// the output's inertia alone (the least any rigid group has) times the step is at most
    /// [`MAX_LOAD_STIFFNESS_H`]. Or the output is at rest at both ends (within [`REST_RADPS`]):
    /// a vehicle held by the brake, whose stiff mode the step does not excite.
    fn load_not_stiff(&self, u: &Inputs, s: &State) -> bool {
        let p = &self.pt.p.driveline;
        let h = self.steps_per_cycle as f64 * self.dt;
        let j = self.pt.inertias()[OUT];
        let ok = |w: f64| load_stiffness(p, w, u.brake) / j * h <= MAX_LOAD_STIFFNESS_H;
        let (w0, w1) = (self.s.w_out, s.w_out);
        let at_rest = |w: f64| w.abs() <= REST_RADPS;
        (at_rest(w0) && at_rest(w1)) || (w0 * w1 > 0.0 && ok(w0) && ok(w1))
    }
}

/// A latched input fresh at the cycle's first step is still fresh at `t_last`, a stale one still
/// stale (freshness only ever ends, so the steps between agree).
fn keeps_freshness<T: Copy>(l: &Latched<T>, t_last: Duration, limit: Duration) -> bool {
    l.msg.is_none() || (t_last.saturating_sub(l.at) < limit) == l.fresh
}

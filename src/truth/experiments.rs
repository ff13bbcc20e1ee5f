//! The truth's rig experiments (test-rig mode: the input side held at a dyno speed, both clutch
//! outputs braked so the slip is the dyno speed; the clutches driven by position requests; both
//! clutches open while the dyno changes speed and during the cooling phases).
//!
//! Two training and two validation records, each under 400 s, with contrast in every variable the
//! classes depend on: dyno speeds from 10 to 2200 rpm, clamp levels up to 7.0 mm (x_to,max is
//! 7.2 mm), trapezoids, staircases, triangles and waves (direction changes for play), both clutches
//! engaged at once at different levels, packs soaked at 25 to 270 °C, cooling phases at different
//! dyno speeds, housing temperature constant or slowly rising. These profiles differ on purpose
//! from those of the plant-based `ddct gap experiment`.

/// Sampling period of the records (s).
pub const SAMPLE_S: f64 = 0.01;

/// Bearing request while a clutch is open (mm).
pub const X_OPEN_MM: f64 = 0.0;

/// A position request shape of one engagement (times in s from its start, positions in mm).
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// Step to `pre` (the fill), ramp to `peak` over `ramp`, hold `hold`, open.
    Trapezoid {
        pre: f64,
        peak: f64,
        ramp: f64,
        hold: f64,
    },
    /// Step to `pre`, then steps through `levels` (level, duration), open.
    Staircase { pre: f64, levels: Vec<(f64, f64)> },
    /// Step to `pre`, ramp to `peak` over `up`, back to `pre` over `down`, open.
    Triangle {
        pre: f64,
        peak: f64,
        up: f64,
        down: f64,
    },
    /// Step to `mid − amp`, then `mid − amp·cos(2πt/period)` for `cycles` periods, open.
    Wave {
        mid: f64,
        amp: f64,
        period: f64,
        cycles: f64,
    },
}

/// Fill time before a ramp starts (s).
const FILL_S: f64 = 0.15;

impl Shape {
    pub fn duration(&self) -> f64 {
        match self {
            Shape::Trapezoid { ramp, hold, .. } => FILL_S + ramp + hold,
            Shape::Staircase { levels, .. } => FILL_S + levels.iter().map(|l| l.1).sum::<f64>(),
            Shape::Triangle { up, down, .. } => FILL_S + up + down,
            Shape::Wave { period, cycles, .. } => FILL_S + period * cycles,
        }
    }

    /// Request at `tau` s after the start (X_OPEN_MM outside the shape).
    pub fn at(&self, tau: f64) -> f64 {
        if tau < 0.0 || tau >= self.duration() {
            return X_OPEN_MM;
        }
        match self {
            Shape::Trapezoid {
                pre,
                peak,
                ramp,
                hold: _,
            } => {
                if tau < FILL_S {
                    *pre
                } else if tau < FILL_S + ramp {
                    pre + (peak - pre) * (tau - FILL_S) / ramp
                } else {
                    *peak
                }
            }
            Shape::Staircase { pre, levels } => {
                if tau < FILL_S {
                    return *pre;
                }
                let mut t0 = FILL_S;
                for (x, d) in levels {
                    if tau < t0 + d {
                        return *x;
                    }
                    t0 += d;
                }
                X_OPEN_MM
            }
            Shape::Triangle {
                pre,
                peak,
                up,
                down,
            } => {
                if tau < FILL_S {
                    *pre
                } else if tau < FILL_S + up {
                    pre + (peak - pre) * (tau - FILL_S) / up
                } else {
                    peak - (peak - pre) * (tau - FILL_S - up) / down
                }
            }
            Shape::Wave {
                mid,
                amp,
                period,
                cycles: _,
            } => {
                if tau < FILL_S {
                    mid - amp
                } else {
                    mid - amp * (2.0 * std::f64::consts::PI * (tau - FILL_S) / period).cos()
                }
            }
        }
    }
}

/// One engagement of one clutch.
#[derive(Debug, Clone, PartialEq)]
pub struct Engagement {
    pub clutch: usize,
    pub t0: f64,
    pub shape: Shape,
}

/// A rig record's definition.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordDef {
    pub name: &'static str,
    pub duration_s: f64,
    /// Soak temperature of the whole pack at the start (°C).
    pub theta0_c: f64,
    /// Housing air: θ_h(t) = θ_h0 + rate·t (°C, °C/s).
    pub housing0_c: f64,
    pub housing_rate_c_per_s: f64,
    /// Dyno speed knots (t s, rpm), linear in between.
    pub speed: Vec<(f64, f64)>,
    pub engagements: Vec<Engagement>,
}

impl RecordDef {
    /// Dyno speed (rad/s) at `t`.
    pub fn speed_radps(&self, t: f64) -> f64 {
        // The knots are in time order (a timeline only moves forward): the first knot after
        // `t` by bisection.
        let k = &self.speed;
        self.speed_in(t, k.partition_point(|p| p.0 <= t).min(k.len() - 1))
    }

    /// [`Self::speed_radps`] with the knot searched from `hint` (the last call's): a step or two
    /// for the slowly advancing times of a simulation, whose millions of calls a bisection over
    /// a long record's knots would dominate.
    pub fn speed_radps_from(&self, t: f64, hint: &mut usize) -> f64 {
        let k = &self.speed;
        let mut j = (*hint).min(k.len() - 1);
        while j > 0 && k[j - 1].0 > t {
            j -= 1;
        }
        while j + 1 < k.len() && k[j].0 <= t {
            j += 1;
        }
        *hint = j;
        self.speed_in(t, j)
    }

    /// The speed at `t` on the segment ending at knot `j` (the first knot after `t`, or the last).
    fn speed_in(&self, t: f64, j: usize) -> f64 {
        let k = &self.speed;
        let rpm = if t <= k[0].0 {
            k[0].1
        } else if t >= k[k.len() - 1].0 {
            k[k.len() - 1].1
        } else {
            let (a, b) = (k[j - 1], k[j]);
            if b.0 > a.0 {
                a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0)
            } else {
                b.1
            }
        };
        rpm * std::f64::consts::PI / 30.0
    }

    pub fn housing_c(&self, t: f64) -> f64 {
        self.housing0_c + self.housing_rate_c_per_s * t
    }

    /// The request of clutch `i` as the bench's controller sends it: held over each 10 ms cycle.
    pub fn request(&self, i: usize, t: f64) -> f64 {
        self.raw_request(i, Self::cycle_start(t))
    }

    /// Both clutches' [`Self::request`] at `t`, taken from `held` (the cycle start and the
    /// requests of the last call) while `t` is in the same cycle: the search over the
    /// engagements runs once per cycle, not at every step of a simulation.
    pub fn requests_held(&self, t: f64, held: &mut (f64, [f64; 2])) -> [f64; 2] {
        let tk = Self::cycle_start(t);
        if tk.to_bits() != held.0.to_bits() {
            *held = (tk, [self.raw_request(0, tk), self.raw_request(1, tk)]);
        }
        held.1
    }

    /// The start of the 10 ms controller cycle holding `t`.
    fn cycle_start(t: f64) -> f64 {
        (t / SAMPLE_S + 1e-9).floor() * SAMPLE_S
    }

    fn raw_request(&self, i: usize, t: f64) -> f64 {
        for e in &self.engagements {
            if e.clutch == i && t >= e.t0 && t < e.t0 + e.shape.duration() {
                return e.shape.at(t - e.t0);
            }
        }
        X_OPEN_MM
    }

    pub fn samples(&self) -> usize {
        (self.duration_s / SAMPLE_S).round() as usize + 1
    }
}

/// Builds a record's timeline.
struct Timeline {
    t: f64,
    rpm: f64,
    speed: Vec<(f64, f64)>,
    engagements: Vec<Engagement>,
}

impl Timeline {
    fn new(rpm: f64) -> Self {
        Timeline {
            t: 0.0,
            rpm,
            speed: vec![(0.0, rpm)],
            engagements: Vec::new(),
        }
    }
    /// Changes the dyno speed (both clutches open) over `ramp` s.
    fn speed(&mut self, rpm: f64, ramp: f64) {
        if rpm != self.rpm {
            self.speed.push((self.t, self.rpm));
            self.speed.push((self.t + ramp, rpm));
            self.rpm = rpm;
            self.t += ramp;
        }
    }
    fn wait(&mut self, s: f64) {
        self.t += s;
    }
    fn engage(&mut self, clutch: usize, shape: Shape) {
        let d = shape.duration();
        self.engagements.push(Engagement {
            clutch,
            t0: self.t,
            shape,
        });
        self.t += d;
    }
    /// Both clutches engaged at once: clutch 1 with `a`, clutch 2 with `b` starting `offset` later.
    fn both(&mut self, a: Shape, b: Shape, offset: f64) {
        let end = (a.duration()).max(offset + b.duration());
        self.engagements.push(Engagement {
            clutch: 0,
            t0: self.t,
            shape: a,
        });
        self.engagements.push(Engagement {
            clutch: 1,
            t0: self.t + offset,
            shape: b,
        });
        self.t += end;
    }
    fn finish(
        mut self,
        name: &'static str,
        theta0_c: f64,
        housing0_c: f64,
        rate: f64,
    ) -> RecordDef {
        self.speed.push((self.t, self.rpm));
        RecordDef {
            name,
            duration_s: (self.t / SAMPLE_S).round() * SAMPLE_S,
            theta0_c,
            housing0_c,
            housing_rate_c_per_s: rate,
            speed: self.speed,
            engagements: self.engagements,
        }
    }
}

fn trap(pre: f64, peak: f64, ramp: f64, hold: f64) -> Shape {
    Shape::Trapezoid {
        pre,
        peak,
        ramp,
        hold,
    }
}

fn tri(pre: f64, peak: f64, up: f64, down: f64) -> Shape {
    Shape::Triangle {
        pre,
        peak,
        up,
        down,
    }
}

fn stair(pre: f64, levels: &[(f64, f64)]) -> Shape {
    Shape::Staircase {
        pre,
        levels: levels.to_vec(),
    }
}

fn wave(mid: f64, amp: f64, period: f64, cycles: f64) -> Shape {
    Shape::Wave {
        mid,
        amp,
        period,
        cycles,
    }
}

/// Training 1: a cold pack heated by engagements that sweep speed and clamp level, both clutches
/// together now and then, then cooling at high dyno speed.
pub fn train_sweep() -> RecordDef {
    let mut tl = Timeline::new(1500.0);
    tl.wait(3.0);
    let plan: [(f64, Shape); 10] = [
        (1500.0, trap(3.0, 5.9, 0.8, 2.2)),
        (2200.0, trap(3.0, 5.6, 0.6, 2.4)),
        (800.0, tri(3.0, 6.4, 1.2, 1.2)),
        (300.0, trap(3.0, 6.6, 0.8, 1.2)),
        (60.0, trap(3.0, 7.0, 1.0, 1.0)),
        (1200.0, stair(3.0, &[(5.4, 0.8), (6.1, 1.0), (5.7, 0.8)])),
        (20.0, tri(3.0, 6.8, 1.0, 1.0)),
        (1800.0, trap(3.0, 5.8, 0.5, 2.2)),
        (500.0, wave(6.0, 0.35, 1.0, 2.0)),
        (120.0, trap(3.0, 6.9, 0.8, 1.0)),
    ];
    for round in 0..5 {
        for (j, (rpm, shape)) in plan.iter().enumerate() {
            tl.speed(*rpm, 0.6);
            tl.wait(0.4);
            tl.engage((round + j) % 2, shape.clone());
            tl.wait(0.6);
        }
        // Both clutches at once, at different levels.
        tl.speed(700.0, 0.6);
        tl.wait(0.4);
        tl.both(trap(3.0, 5.8, 0.6, 1.6), trap(3.0, 5.2, 0.4, 1.0), 0.5);
        tl.wait(0.6);
    }
    tl.speed(2000.0, 1.0);
    tl.wait(90.0);
    tl.finish("train_sweep", 25.0, 25.0, 0.02)
}

/// Training 2: a pack soaked at 270 °C, low-slip engagements (static friction regime) to high
/// clamp loads and medium-speed ones, housing warming, cooling at high dyno speed.
pub fn train_hot() -> RecordDef {
    let mut tl = Timeline::new(20.0);
    tl.wait(3.0);
    let plan: [(f64, Shape); 8] = [
        (10.0, trap(2.6, 6.8, 1.0, 1.2)),
        (25.0, tri(2.6, 6.2, 1.0, 1.0)),
        (50.0, stair(2.6, &[(4.6, 0.8), (5.8, 0.8), (6.6, 0.8)])),
        (120.0, trap(2.6, 5.0, 0.8, 1.2)),
        (400.0, tri(2.6, 4.9, 0.8, 0.8)),
        (900.0, trap(2.6, 4.4, 0.6, 1.4)),
        (15.0, trap(2.6, 7.0, 1.2, 1.0)),
        (200.0, wave(4.9, 0.3, 1.2, 2.0)),
    ];
    for round in 0..5 {
        for (j, (rpm, shape)) in plan.iter().enumerate() {
            tl.speed(*rpm, 0.6);
            tl.wait(0.4);
            tl.engage((round + j + 1) % 2, shape.clone());
            tl.wait(1.0);
        }
        tl.speed(40.0, 0.6);
        tl.wait(0.4);
        tl.both(trap(2.6, 5.4, 0.6, 1.6), trap(2.6, 6.4, 0.6, 1.0), 0.3);
        tl.wait(1.0);
    }
    tl.speed(2200.0, 1.0);
    tl.wait(90.0);
    tl.finish("train_hot", 270.0, 60.0, 0.04)
}

/// Validation 1: a warm pack, staircases, waves and triangles at other speeds and levels, both
/// clutches together, cooling at low dyno speed.
pub fn validate_mixed() -> RecordDef {
    let mut tl = Timeline::new(1000.0);
    tl.wait(3.0);
    let plan: [(f64, Shape); 9] = [
        (1800.0, stair(3.0, &[(5.3, 1.0), (5.9, 1.2)])),
        (1000.0, tri(3.0, 6.3, 1.4, 1.0)),
        (400.0, stair(3.0, &[(6.4, 0.8), (5.8, 0.8), (6.2, 0.6)])),
        (100.0, wave(6.1, 0.45, 1.4, 1.5)),
        (15.0, trap(3.0, 6.9, 1.4, 0.8)),
        (2200.0, trap(3.0, 5.5, 0.4, 2.4)),
        (700.0, stair(3.0, &[(5.6, 0.7), (6.4, 0.9)])),
        (40.0, tri(3.0, 7.0, 1.2, 1.4)),
        (1400.0, wave(5.7, 0.3, 0.8, 2.5)),
    ];
    for round in 0..5 {
        for (j, (rpm, shape)) in plan.iter().enumerate() {
            tl.speed(*rpm, 0.6);
            tl.wait(0.4);
            tl.engage((round + j) % 2, shape.clone());
            tl.wait(0.8);
        }
        tl.speed(250.0, 0.6);
        tl.wait(0.4);
        tl.both(
            stair(3.0, &[(5.0, 0.8), (6.2, 0.8)]),
            trap(3.0, 6.0, 0.5, 1.4),
            0.2,
        );
        tl.wait(0.8);
    }
    tl.speed(300.0, 1.0);
    tl.wait(80.0);
    tl.finish("validate_mixed", 40.0, 30.0, 0.0)
}

/// Validation 2: a pack soaked at 200 °C, triangles to near x_to,max and trapezoids at 10 to
/// 600 rpm, both clutches together, cooling at medium dyno speed.
pub fn validate_hot() -> RecordDef {
    let mut tl = Timeline::new(30.0);
    tl.wait(3.0);
    let plan: [(f64, Shape); 8] = [
        (30.0, tri(2.8, 7.0, 1.6, 1.6)),
        (600.0, trap(2.8, 4.8, 0.6, 1.6)),
        (10.0, stair(2.8, &[(5.0, 0.8), (6.0, 0.8), (6.8, 0.8)])),
        (250.0, tri(2.8, 5.6, 1.0, 1.0)),
        (75.0, trap(2.8, 6.2, 0.8, 1.2)),
        (1100.0, trap(2.8, 4.5, 0.5, 1.5)),
        (20.0, wave(5.8, 0.5, 1.5, 1.5)),
        (150.0, stair(2.8, &[(5.9, 0.8), (5.2, 0.8)])),
    ];
    for round in 0..5 {
        for (j, (rpm, shape)) in plan.iter().enumerate() {
            tl.speed(*rpm, 0.6);
            tl.wait(0.4);
            tl.engage((round + j + 1) % 2, shape.clone());
            tl.wait(1.0);
        }
        tl.speed(60.0, 0.6);
        tl.wait(0.4);
        tl.both(tri(2.8, 6.5, 0.8, 0.8), trap(2.8, 5.0, 0.6, 1.4), 0.4);
        tl.wait(1.0);
    }
    tl.speed(1000.0, 1.0);
    tl.wait(70.0);
    tl.finish("validate_hot", 200.0, 45.0, 0.03)
}

/// The training records, in order.
pub fn training() -> Vec<RecordDef> {
    vec![train_sweep(), train_hot()]
}

/// The validation records, in order.
pub fn validation() -> Vec<RecordDef> {
    vec![validate_mixed(), validate_hot()]
}

/// Every record in order: training, then validation.
pub fn all() -> Vec<RecordDef> {
    let mut v = training();
    v.extend(validation());
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The knot found by bisection, or searched from the last one, is the one a scan from the
    /// start finds, at every 1 ms of every record of the experiments (and half a step on); the
    /// requests held over a cycle are the requests.
    #[test]
    fn the_dyno_speed_by_bisection_is_the_scanned_one() {
        // The segment's knot found by a scan, the interpolation the record's own.
        let scanned = |rec: &RecordDef, t: f64| -> f64 {
            let k = &rec.speed;
            let j = k.iter().position(|p| p.0 > t).unwrap_or(k.len() - 1);
            rec.speed_in(t, j)
        };
        let recs = all();
        assert!(recs.iter().any(|r| r.speed.len() > 3));
        for rec in &recs {
            assert!(
                rec.speed.windows(2).all(|w| w[0].0 <= w[1].0),
                "{}",
                rec.name
            );
            let mut hint = 0;
            for j in 0..(rec.duration_s * 1000.0) as usize + 10 {
                let t = j as f64 * 1e-3;
                let want = scanned(rec, t).to_bits();
                assert_eq!(rec.speed_radps(t).to_bits(), want);
                assert_eq!(rec.speed_radps_from(t, &mut hint).to_bits(), want);
                // A stage half a step on, then back.
                let mut h2 = hint;
                let _ = rec.speed_radps_from(t + 5e-4, &mut h2);
                assert_eq!(rec.speed_radps_from(t, &mut h2).to_bits(), want);
            }
            let mut held = (f64::NAN, [0.0; 2]);
            for j in 0..(rec.duration_s * 2000.0) as usize {
                let t = j as f64 * 5e-4;
                let r = rec.requests_held(t, &mut held);
                for (i, r) in r.iter().enumerate() {
                    assert_eq!(r.to_bits(), rec.request(i, t).to_bits());
                }
            }
            let mut far = rec.speed.len() + 5;
            assert_eq!(
                rec.speed_radps_from(0.0, &mut far).to_bits(),
                scanned(rec, 0.0).to_bits()
            );
        }
    }

    #[test]
    fn records_are_moderate_and_engagements_do_not_overlap_per_clutch() {
        for r in all() {
            assert!(
                r.duration_s > 120.0 && r.duration_s <= 400.0,
                "{} {}",
                r.name,
                r.duration_s
            );
            for i in 0..2 {
                let mut e: Vec<_> = r.engagements.iter().filter(|e| e.clutch == i).collect();
                e.sort_by(|a, b| a.t0.total_cmp(&b.t0));
                for w in e.windows(2) {
                    assert!(
                        w[0].t0 + w[0].shape.duration() <= w[1].t0 + 1e-9,
                        "{}",
                        r.name
                    );
                }
            }
            // The dyno changes speed only while both clutches are open.
            for k in 0..r.samples() {
                let t = k as f64 * SAMPLE_S;
                let engaged = (0..2).any(|i| r.request(i, t) > X_OPEN_MM);
                if engaged {
                    let (a, b) = (r.speed_radps(t - 0.02), r.speed_radps(t + 0.02));
                    assert!((a - b).abs() < 1e-9, "{} speed changes at {t}", r.name);
                }
            }
        }
    }
}

//! Driveline of the dual-clutch transmission, paper Sect. 5.1, (18)–(20), with road grade, brake,
//! per-clutch stick/slip, gear selection and synchronisers.
//!
//! Four rotating bodies: flywheel/engine (ω_f, J_eq), odd clutch disk + input shaft (ω_c1, J_c1),
//! even clutch disk + input shaft (ω_c2, J_c2) and output/vehicle (ω_out, J_d = m·R_w² + J_wheels).
//! Links: an engaged gear makes ω_c = k·ω_out with k = i_g·i_f (20); a locked clutch makes
//! ω_c = ω_f. Linked bodies form rigid groups ([`Groups`]) that accelerate together under the sum
//! of their external torques (the reduction (21)–(22) of the paper, generalised to any set of
//! links); a slipping clutch acts with T_fc of (13) on the clutch (+) and the flywheel (−), (18a)–(18c).
//! A neutral shaft spins freely with its clutch inertia. The constraint torque a locked clutch has
//! to carry is [`Groups::link_torque`]; the stick/slip rule itself lives in the powertrain step.
//!
//! Load (19) plus grade and brake, referred to the wheels:
//! T_load = f0·s(v) + f1·v + f2·v|v| + m·g·sin(atan(grade))·R_w + T_brake·s(v), v = R_w·ω_out,
//! where s(v) = tanh(v/v_ε) regularises the sign so a car at rest is held, not pushed backwards.

use super::gear::Gear;
use super::params::DrivelineParams;
use serde::{Deserialize, Serialize};

/// Body indices.
pub(crate) const F: usize = 0;
pub(crate) const C1: usize = 1;
pub(crate) const C2: usize = 2;
pub const OUT: usize = 3;

/// Overall ratio k = i_g·i_f of a gear (ω_c = k·ω_out); negative for reverse; `None` for
/// neutral.
pub fn overall_ratio(p: &DrivelineParams, gear: Gear) -> Option<f64> {
    let ig = match gear {
        Gear::G1 => p.ratio_g1,
        Gear::G2 => p.ratio_g2,
        Gear::G3 => p.ratio_g3,
        Gear::G4 => p.ratio_g4,
        Gear::G5 => p.ratio_g5,
        Gear::G6 => p.ratio_g6,
        Gear::R => -p.ratio_reverse,
        Gear::N => return None,
    };
    Some(ig * p.final_drive)
}

/// Inertias of the four bodies (kg·m²).
pub fn inertias(p: &DrivelineParams) -> [f64; 4] {
    [
        p.j_eq_kgm2,
        p.j_c1_kgm2,
        p.j_c2_kgm2,
        p.vehicle_mass_kg * p.wheel_radius_m.powi(2) + p.j_wheels_kgm2,
    ]
}

/// Road load at the wheels (N·m): (19) with regularised sign, plus grade and brake.
/// `grade` is rise over run (0.05 = 5 %), `brake` a fraction 0..1.
pub fn load_torque(p: &DrivelineParams, w_out_radps: f64, grade: f64, brake: f64) -> f64 {
    let grade = if grade.is_finite() { grade } else { 0.0 };
    load_torque_graded(p, w_out_radps, grade_torque(p, grade), brake)
}

/// [`load_torque`] with the grade torque [`grade_torque`] already computed (it holds over a step
/// with held inputs; the speed-dependent part does not).
#[inline]
pub(crate) fn load_torque_graded(
    p: &DrivelineParams,
    w_out_radps: f64,
    grade_nm: f64,
    brake: f64,
) -> f64 {
    let v = p.wheel_radius_m * w_out_radps;
    let s = (v / p.load_smoothing_m_per_s).tanh();
    let brake = brake_fraction(brake);
    p.f0_nm * s
        + p.f1_nm_s_per_m * v
        + p.f2_nm_s2_per_m2 * v * v.abs()
        + grade_nm
        + p.brake_max_nm * brake * s
}

/// The brake input as the load reads it: a fraction 0..1, a non-finite value as released.
#[inline]
fn brake_fraction(brake: f64) -> f64 {
    if brake.is_finite() {
        brake.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// ∂T_load/∂ω_out of [`load_torque_graded`] (N·m·s/rad, ≥ 0): the stiffness of the road load,
/// largest at standstill where the constant terms and the brake are regularised over
/// `load_smoothing_m_per_s` (what limits an explicit step there).
pub(crate) fn load_stiffness(p: &DrivelineParams, w_out_radps: f64, brake: f64) -> f64 {
    let r = p.wheel_radius_m;
    let v = r * w_out_radps;
    let eps = p.load_smoothing_m_per_s;
    let brake = brake_fraction(brake);
    let sech2 = 1.0 - (v / eps).tanh().powi(2);
    r * ((p.f0_nm + p.brake_max_nm * brake) * sech2 / eps
        + p.f1_nm_s_per_m
        + 2.0 * p.f2_nm_s2_per_m2 * v.abs())
}

/// Grade torque m·g·sin(atan(grade))·R_w (N·m).
pub(crate) fn grade_torque(p: &DrivelineParams, grade: f64) -> f64 {
    if grade == 0.0 {
        // Level road (most steps): no atan/sin.
        return 0.0;
    }
    p.vehicle_mass_kg * p.gravity_m_per_s2 * grade.atan().sin() * p.wheel_radius_m
}

/// Slip speeds (20): ω_fc1 = ω_f − ω_c1, ω_fc2 = ω_f − ω_c2.
#[inline]
pub(crate) fn slips(w: &[f64; 4]) -> [f64; 2] {
    [w[F] - w[C1], w[F] - w[C2]]
}

/// Kinematic links between bodies.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Links {
    /// Clutch 1 locked (ω_c1 = ω_f).
    pub clutch1: bool,
    /// Clutch 2 locked (ω_c2 = ω_f).
    pub clutch2: bool,
    /// Odd gear engaged: ω_c1 = k_odd·ω_out.
    pub k_odd: Option<f64>,
    /// Even gear engaged: ω_c2 = k_even·ω_out.
    pub k_even: Option<f64>,
}

impl Links {
    /// Edges (a, b, ρ) meaning ω_a = ρ·ω_b; index 0/1 are the clutches, 2/3 the gears.
    fn edges(&self) -> [Option<(usize, usize, f64)>; 4] {
        [
            self.clutch1.then_some((C1, F, 1.0)),
            self.clutch2.then_some((C2, F, 1.0)),
            self.k_odd.map(|k| (C1, OUT, k)),
            self.k_even.map(|k| (C2, OUT, k)),
        ]
    }
}

/// The system of links closes a loop with inconsistent ratios (both clutches locked with both
/// gears engaged): the gearbox would be tied up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("links tie up the gearbox (both clutches locked with two different gears engaged)")]
pub struct TieUp;

/// Rigid groups: body i turns at `r[i]·ω[root[i]]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Groups {
    pub links: Links,
    pub root: [usize; 4],
    pub r: [f64; 4],
}

impl Groups {
    /// Builds the groups of a set of links.
    pub fn new(links: Links) -> Result<Groups, TieUp> {
        let edges = links.edges();
        let mut root = [usize::MAX; 4];
        let mut r = [0.0; 4];
        for start in 0..4 {
            if root[start] != usize::MAX {
                continue;
            }
            root[start] = start;
            r[start] = 1.0;
            let mut stack = [0usize; 4];
            let mut n = 1;
            stack[0] = start;
            while n > 0 {
                n -= 1;
                let node = stack[n];
                for (a, b, rho) in edges.iter().flatten().copied() {
                    let (other, r_other) = if b == node {
                        (a, rho * r[node])
                    } else if a == node {
                        (b, r[node] / rho)
                    } else {
                        continue;
                    };
                    if root[other] == usize::MAX {
                        root[other] = start;
                        r[other] = r_other;
                        stack[n] = other;
                        n += 1;
                    } else if (r[other] - r_other).abs() > 1e-9 * r_other.abs().max(1e-9) {
                        return Err(TieUp);
                    }
                }
            }
        }
        Ok(Groups { links, root, r })
    }

    /// Accelerations (rad/s²) of the four bodies under external torques `t` (N·m).
    pub fn accelerations(&self, j: &[f64; 4], t: &[f64; 4]) -> [f64; 4] {
        let mut jg = [0.0; 4];
        let mut tg = [0.0; 4];
        for i in 0..4 {
            let g = self.root[i];
            jg[g] += self.r[i] * self.r[i] * j[i];
            tg[g] += self.r[i] * t[i];
        }
        std::array::from_fn(|i| {
            let g = self.root[i];
            self.r[i] * tg[g] / jg[g]
        })
    }

    /// Torque carried by link `edge` (0: clutch 1, 1: clutch 2, 2: odd gear, 3: even gear) from
    /// its `b` side into its `a` side (for a clutch: from the flywheel into the clutch disk, the
    /// sign convention of T_fc), given the accelerations `acc` and external torques `t`.
    /// Zero when the link is not active.
    pub fn link_torque(&self, edge: usize, j: &[f64; 4], t: &[f64; 4], acc: &[f64; 4]) -> f64 {
        let edges = self.links.edges();
        let Some((a, _b, _)) = edges[edge] else {
            return 0.0;
        };
        // Bodies reachable from `a` without crossing `edge` (the group is a tree).
        let mut side = [false; 4];
        side[a] = true;
        let mut changed = true;
        while changed {
            changed = false;
            for (k, e) in edges.iter().enumerate() {
                if k == edge {
                    continue;
                }
                if let Some((x, y, _)) = e {
                    if side[*x] != side[*y] {
                        side[*x] = true;
                        side[*y] = true;
                        changed = true;
                    }
                }
            }
        }
        let ra = self.r[a];
        (0..4)
            .filter(|&i| side[i])
            .map(|i| self.r[i] / ra * (j[i] * acc[i] - t[i]))
            .sum()
    }

    /// Impulsive projection of speeds onto the links: each group takes the common speed that
    /// conserves its generalised momentum Σ rᵢJᵢωᵢ. Returns the new speeds and the kinetic energy
    /// lost (J, ≥ 0).
    pub fn project(&self, j: &[f64; 4], w: &[f64; 4]) -> ([f64; 4], f64) {
        let mut pg = [0.0; 4];
        let mut jg = [0.0; 4];
        for i in 0..4 {
            let g = self.root[i];
            pg[g] += self.r[i] * j[i] * w[i];
            jg[g] += self.r[i] * self.r[i] * j[i];
        }
        let out: [f64; 4] = std::array::from_fn(|i| {
            let g = self.root[i];
            self.r[i] * pg[g] / jg[g]
        });
        let ke = |w: &[f64; 4]| 0.5 * (0..4).map(|i| j[i] * w[i] * w[i]).sum::<f64>();
        let loss = (ke(w) - ke(&out)).max(0.0);
        (out, loss)
    }
}

/// Gear selector of one input shaft. While the fork moves towards `target` the shaft is in
/// neutral (`engaged == Gear::N`) and the synchroniser pulls the shaft towards the gear's speed; the dog
/// engages once `select_time` has elapsed and the speeds match within `sync_tolerance`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct GearShaft {
    /// Engaged gear (`N`: none).
    pub engaged: Gear,
    /// Requested gear.
    pub target: Gear,
    /// Time since the current selection started (s).
    pub timer_s: f64,
}

impl GearShaft {
    /// A shaft with `gear` engaged and nothing pending.
    pub fn engaged(gear: Gear) -> Self {
        Self {
            engaged: gear,
            target: gear,
            timer_s: 0.0,
        }
    }

    /// True while the synchroniser works (a gear is being selected).
    pub fn syncing(&self) -> bool {
        self.target != Gear::N && self.engaged != self.target
    }

    /// Takes a new request; a change disengages the current gear at once.
    pub fn request(&mut self, gear: Gear) {
        if gear != self.target {
            self.target = gear;
            self.engaged = Gear::N;
            self.timer_s = 0.0;
        }
    }
}

/// Synchroniser torque (N·m) on the input shaft of a syncing selector, acting against the speed
/// difference Δ = ω_c − k·ω_out; the output receives k times its opposite.
pub(crate) fn sync_torque(p: &DrivelineParams, w_c: f64, k: f64, w_out: f64) -> f64 {
    -p.sync_torque_nm * ((w_c - k * w_out) / p.sync_smoothing_radps).tanh()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Params;

    /// The load's stiffness is the derivative of the load torque (central differences), from
    /// standstill through the regularised band to cruising, with and without the brake.
    #[test]
    fn load_stiffness_is_the_derivative_of_the_load() {
        let p = Params::default().driveline;
        for brake in [0.0, 0.4, 1.0] {
            for v in [-20.0, -0.02, -0.004, 0.0, 0.003, 0.01, 0.05, 1.0, 30.0] {
                let w = v / p.wheel_radius_m;
                let h = 1e-6 * w.abs().max(1e-3);
                let fd = (load_torque_graded(&p, w + h, 0.0, brake)
                    - load_torque_graded(&p, w - h, 0.0, brake))
                    / (2.0 * h);
                let k = load_stiffness(&p, w, brake);
                assert!(
                    (k - fd).abs() <= 1e-5 * fd.abs().max(1.0),
                    "v {v} brake {brake}: {k} {fd}"
                );
            }
        }
    }

    #[test]
    fn groups_and_rigid_acceleration() {
        let p = Params::default().driveline;
        let j = inertias(&p);
        let k = overall_ratio(&p, Gear::G1).unwrap();
        let g = Groups::new(Links {
            clutch1: true,
            k_odd: Some(k),
            ..Default::default()
        })
        .unwrap();
        assert_eq!(g.root, [0, 0, 2, 0]);
        let t = [100.0, 0.0, 0.0, -50.0];
        let a = g.accelerations(&j, &t);
        let expected = (100.0 - 50.0 / k) / (j[0] + j[1] + j[3] / (k * k));
        assert!((a[0] - expected).abs() < 1e-12 * expected.abs());
        assert!((a[3] - expected / k).abs() < 1e-12);
        assert_eq!(a[2], 0.0);
        // The clutch carries the engine torque minus what accelerates the flywheel.
        let tc = g.link_torque(0, &j, &t, &a);
        assert!((tc - (100.0 - j[0] * a[0])).abs() < 1e-9);
    }

    #[test]
    fn tie_up_detected() {
        let p = Params::default().driveline;
        let l = Links {
            clutch1: true,
            clutch2: true,
            k_odd: overall_ratio(&p, Gear::G1),
            k_even: overall_ratio(&p, Gear::G2),
        };
        assert_eq!(Groups::new(l), Err(TieUp));
    }

    #[test]
    fn projection_conserves_momentum() {
        let p = Params::default().driveline;
        let j = inertias(&p);
        let g = Groups::new(Links {
            clutch1: true,
            ..Default::default()
        })
        .unwrap();
        let (w, loss) = g.project(&j, &[100.0, 90.0, 5.0, 1.0]);
        assert!((w[0] - w[1]).abs() < 1e-12);
        assert!((j[0] * w[0] + j[1] * w[1] - (j[0] * 100.0 + j[1] * 90.0)).abs() < 1e-12);
        assert!(loss > 0.0);
        assert_eq!(w[2], 5.0);
    }

    #[test]
    fn load_holds_at_rest_and_grade_sign() {
        let p = Params::default().driveline;
        assert_eq!(load_torque(&p, 0.0, 0.0, 0.0), 0.0);
        assert!(load_torque(&p, 10.0, 0.0, 0.0) > p.f0_nm);
        let g = grade_torque(&p, 0.1);
        assert!((g - 1500.0 * 9.81 * (0.1f64).atan().sin() * 0.31).abs() < 1e-9);
    }
}

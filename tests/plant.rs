//! Integration tests of the plant (issue 5): every reality effect changes what its physics says
//! and nothing else; every fault kind shows on the frames in its window only; friction energy
//! equals the heat the thermal model takes; the rig experiment of the paper's Sect. 3.3 (Fig. 6);
//! sensors, inputs, modes and the daemon loop. Expectations are independent: analytic solutions,
//! the paper's equations evaluated with `model::clutch` directly, and nominal runs.

#![allow(clippy::field_reassign_with_default)]

use ddct::can::e2e::{counter_of, e2e_crc, CRC_BYTE};
use ddct::can::messages::{
    ids, message_def, BenchTemps, BenchTorque, DctActuators, DctSensors, DrvPedal, EngStatus,
    TcuClutchCmd, TcuEngineReq, TcuGearCmd,
};
use ddct::can::{Bus, CanFrame, EndpointConfig, InProcessBus, ManualClock, Received};
use ddct::model::clutch;
use ddct::model::effects::{EffectId, EffectSet};
use ddct::model::engine::RPM;
use ddct::model::gear::Gear;
use ddct::plant::config::SensorNoise;
use ddct::plant::{FaultKind, Mode, OutFrame, Plant, PlantConfig, RigProfile, Truth};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

const MS: Duration = Duration::from_millis(1);

/// Two partial engagements of clutch 1 at 1500 rpm: 0 → 3.5 mm fast, ramp to 5.6 mm over 1 s,
/// hold 0.5 s, release.
const SHORT_PROFILE: &str =
    "input_speed_rpm = 1500\nstart_s = 0.2\n[engagement]\nclutch = 1\ncount = 2\n\
    period_s = 3.0\nt_s = [0.0, 0.2, 1.2, 1.7, 2.0, 3.0]\nx_mm = [0.0, 3.5, 5.6, 5.6, 0.0, 0.0]\n\
    [cooling]\nduration_s = 1.0\n";

fn rig_config(effects: EffectSet, temperature_c: f64) -> PlantConfig {
    let mut c = PlantConfig::load(Path::new("config/plant_rig.toml")).unwrap();
    c.sensors = SensorNoise::default();
    c.effects = effects;
    c.initial.temperature_c = temperature_c;
    c.initial.housing_c = 25.0;
    c.housing.target_c = 25.0;
    c.rig_profile =
        Some(RigProfile::from_toml_str(Path::new("short.toml"), SHORT_PROFILE).unwrap());
    c
}

struct Run {
    /// Truth after every 1 ms step (index k: time k ms).
    truth: Vec<Truth>,
    frames: Vec<OutFrame>,
}

/// Runs a plant for `seconds`, 1 ms per call, feeding `rx(k)` frames at step k.
fn run_with(cfg: PlantConfig, seconds: f64, mut rx: impl FnMut(u64) -> Vec<Received>) -> Run {
    let mut p = Plant::new(cfg);
    let n = (seconds * 1000.0).round() as u64;
    let mut truth = Vec::with_capacity(n as usize + 1);
    let mut frames = Vec::new();
    for k in 0..=n {
        let out = p.step(MS * k as u32, &rx(k));
        truth.push(out.truth);
        frames.extend(out.frames);
    }
    Run { truth, frames }
}

fn run(cfg: PlantConfig, seconds: f64) -> Run {
    run_with(cfg, seconds, |_| Vec::new())
}

fn frames_of(r: &Run, id: u16) -> Vec<&OutFrame> {
    r.frames
        .iter()
        .filter(|f| f.frame.standard_id() == Some(id))
        .collect()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-9)
}

fn single(id: EffectId, v: &[f64]) -> EffectSet {
    EffectSet::single(id, v).unwrap()
}

/// Truth samples where clutch 1 transmits torque.
fn slipping(r: &Run) -> impl Iterator<Item = (usize, &Truth)> {
    r.truth
        .iter()
        .enumerate()
        .filter(|(_, t)| t.outputs.t_fc1_nm > 1.0)
}

// ------------------------------------------------------------------------------------- effects

#[test]
fn spring_stiffness_softens_torque_only_above_room_temperature() {
    let k = -3e-4;
    let fx = single(EffectId::SpringStiffnessTemp, &[k]);
    // Below θ_a = 25 °C (a 10 °C clutch that stays below 25 °C): every frame is the nominal one.
    let cold = |e| {
        let mut c = rig_config(e, 10.0);
        c.initial.housing_c = 10.0;
        c.housing.target_c = 10.0;
        run(c, 1.0)
    };
    let (a, b) = (cold(fx), cold(EffectSet::nominal()));
    assert!(a.truth.iter().all(|t| t.state.thermal.c1 < 25.0));
    assert!(a.truth.iter().any(|t| t.outputs.t_fc1_nm > 20.0));
    assert_eq!(
        a.frames, b.frames,
        "below room temperature the effect must not show"
    );
    // Preheated to 180 °C: T = (13)·(1 + k(θ_c − θ_a)), the kiss point (β) unchanged.
    let hot = run(rig_config(fx, 180.0), 2.2);
    let p = hot_params();
    let mut n = 0;
    for (_, t) in slipping(&hot) {
        let s = &t.state;
        let expect = clutch::torque(&p, s.x1_mm, s.slip(0), s.thermal.c1)
            * (1.0 + k * (s.thermal.c1 - 25.0));
        assert!(
            rel(t.outputs.t_fc1_nm, expect) < 1e-9,
            "{} vs {expect}",
            t.outputs.t_fc1_nm
        );
        assert_eq!(
            t.outputs.beta1,
            ddct::model::thermal::beta(&p, s.x1_mm, s.thermal.c1)
        );
        n += 1;
    }
    assert!(n > 500);
    // And it is a softening of the order the spec says (≈ −4.6 % at 180 °C).
    let nominal = run(rig_config(EffectSet::nominal(), 180.0), 0.6);
    let i = (0..nominal.truth.len())
        .find(|&i| nominal.truth[i].outputs.t_fc1_nm > 5.0)
        .unwrap();
    let r = hot.truth[i].outputs.t_fc1_nm / nominal.truth[i].outputs.t_fc1_nm;
    assert!((r - (1.0 + k * 155.0)).abs() < 1e-3, "ratio {r}");
}

fn hot_params() -> ddct::model::ClutchParams {
    ddct::model::Params::default().clutch
}

#[test]
fn friction_pressure_scales_torque_as_force_to_the_a() {
    let a = 0.85;
    let r = run(
        rig_config(single(EffectId::FrictionPressure, &[a]), 25.0),
        2.2,
    );
    let p = hot_params();
    let area = std::f64::consts::PI * (p.r2_m.powi(2) - p.r1_m.powi(2));
    let mut n = 0;
    for (_, t) in slipping(&r) {
        let s = &t.state;
        let f = clutch::normal_force(&p, s.x1_mm, s.thermal.c1);
        let expect = clutch::torque(&p, s.x1_mm, s.slip(0), s.thermal.c1)
            * (f / (0.24e6 * area)).powf(a - 1.0);
        assert!(rel(t.outputs.t_fc1_nm, expect) < 1e-9);
        // Nothing else: the contact flag is the nominal kiss point's.
        assert_eq!(
            t.outputs.beta1,
            ddct::model::thermal::beta(&p, s.x1_mm, s.thermal.c1)
        );
        n += 1;
    }
    assert!(n > 500);
}

#[test]
fn mu_static_changes_static_capacity_not_the_sliding_torque() {
    let k = -6e-4;
    let fx = single(EffectId::MuStaticTemp, &[k]);
    let a = run(rig_config(fx, 150.0), 2.2);
    let b = run(rig_config(EffectSet::nominal(), 150.0), 2.2);
    // On the rig the slip is 157 rad/s: tanh(γρω)^(1/3) = 1, μ = μ_d — torque, temperatures and
    // every frame are the nominal ones.
    assert_eq!(a.frames, b.frames);
    // The static capacity (what holds a locked clutch) follows μ_s(θ).
    let p = hot_params();
    let mut n = 0;
    for (_, t) in slipping(&a) {
        let s = &t.state;
        let expect =
            clutch::capacity(&p, s.x1_mm, s.thermal.c1) * (1.0 + k * (s.thermal.c1 - 25.0));
        assert!(rel(t.outputs.capacity1_nm, expect) < 1e-9);
        n += 1;
    }
    assert!(n > 500);
}

#[test]
fn facing_asymmetry_uses_the_two_facing_form_with_plate_temperatures() {
    let w = 0.8;
    let mut cfg = rig_config(single(EffectId::FacingAsymmetry, &[w]), 60.0);
    cfg.initial.pp1_c = Some(140.0);
    cfg.initial.cd_c = Some(100.0);
    let r = run(cfg.clone(), 2.2);
    let p = hot_params();
    let mut n = 0;
    for (_, t) in slipping(&r) {
        let s = &t.state;
        let (c, pp, cd) = (s.thermal.c1, s.thermal.pp1, s.thermal.cd);
        let expect = clutch::torque_two_facing(
            &p,
            s.x1_mm,
            s.slip(0),
            c + w * (pp - c),
            c + w * (cd - c),
            c,
        );
        assert!(rel(t.outputs.t_fc1_nm, expect) < 1e-9);
        n += 1;
    }
    assert!(n > 500);
    // At uniform temperatures (11) equals (13): the effect vanishes.
    // (Housing air at 60 °C too, so nothing relaxes apart before the clutch closes.)
    let uniform = |e| {
        let mut c = rig_config(e, 60.0);
        c.initial.housing_c = 60.0;
        c.housing.target_c = 60.0;
        run(c, 1.0)
    };
    let a = uniform(single(EffectId::FacingAsymmetry, &[w]));
    let b = uniform(EffectSet::nominal());
    let first = (0..a.truth.len())
        .find(|&i| b.truth[i].outputs.t_fc1_nm > 0.0)
        .unwrap();
    assert!(
        rel(
            a.truth[first].outputs.t_fc1_nm,
            b.truth[first].outputs.t_fc1_nm
        ) < 1e-6
    );
}

#[test]
fn support_conduction_cools_clutch_disks_and_central_disk_only() {
    let k = 3e-3;
    let a5 = ddct::model::Params::default().thermal5;
    // Both clutches open for the whole run (no profile): pure cooling from 200 °C to 25 °C air.
    let cool = |e| {
        let mut c = rig_config(e, 200.0);
        c.rig_profile = None;
        run(c, 100.0)
    };
    let a = cool(single(EffectId::SupportConduction, &[k]));
    let b = cool(EffectSet::nominal());
    for i in [10_000usize, 50_000, 100_000] {
        let t = i as f64 * 1e-3;
        let s = &a.truth[i].state.thermal;
        // Open clutch: θ̇_c = −(α6 + k)(θ_c − θ_h), θ̇_cd = −(2α8 + k)(θ_cd − θ_h), θ̇_pp = −α2(θ_pp − θ_h).
        let c = 25.0 + 175.0 * (-(a5.alpha6_per_s + k) * t).exp();
        let cd = 25.0 + 175.0 * (-(2.0 * a5.alpha8_per_s + k) * t).exp();
        let pp = 25.0 + 175.0 * (-a5.alpha2_per_s * t).exp();
        assert!(
            (s.c1 - c).abs() < 1e-6 && (s.c2 - c).abs() < 1e-6,
            "{} vs {c}",
            s.c1
        );
        assert!((s.cd - cd).abs() < 1e-6, "{} vs {cd}", s.cd);
        assert!((s.pp1 - pp).abs() < 1e-6);
        // Nothing else: the pressure plates cool exactly as without the effect.
        assert_eq!(s.pp1, b.truth[i].state.thermal.pp1);
    }
    // The torque at a given temperature is the nominal characteristic.
    let r = run(
        rig_config(single(EffectId::SupportConduction, &[k]), 120.0),
        2.2,
    );
    let p = hot_params();
    for (_, t) in slipping(&r) {
        let s = &t.state;
        assert!(
            rel(
                t.outputs.t_fc1_nm,
                clutch::torque(&p, s.x1_mm, s.slip(0), s.thermal.c1)
            ) < 1e-12
        );
    }
}

#[test]
fn backlash_sits_between_measured_actuator_and_bearing() {
    let b = 0.16;
    let a = run(
        rig_config(single(EffectId::ActuatorBacklash, &[b]), 25.0),
        3.2,
    );
    let n = run(rig_config(EffectSet::nominal(), 25.0), 3.2);
    let p = hot_params();
    let mut closing = 0;
    let mut opening = 0;
    for i in 1..a.truth.len() {
        let (t, t0) = (&a.truth[i], &a.truth[i - 1]);
        // The actuator (and so the position sensor) moves exactly as without backlash.
        assert_eq!(t.state.x1_mm, n.truth[i].state.x1_mm);
        // Play operator, direction dependent.
        let x = t.state.x1_mm;
        let expect = if x > t0.x_bearing_mm[0] + b / 2.0 {
            x - b / 2.0
        } else if x < t0.x_bearing_mm[0] - b / 2.0 {
            x + b / 2.0
        } else {
            t0.x_bearing_mm[0]
        };
        assert!((t.x_bearing_mm[0] - expect).abs() < 1e-12);
        if x > t0.state.x1_mm + 1e-6 && (t.x_bearing_mm[0] - (x - b / 2.0)).abs() < 1e-12 {
            closing += 1;
        }
        if x < t0.state.x1_mm - 1e-6 && (t.x_bearing_mm[0] - (x + b / 2.0)).abs() < 1e-12 {
            opening += 1;
        }
        // The clutch sees the bearing.
        let s = &t.state;
        let tq = clutch::torque(&p, t.x_bearing_mm[0], s.slip(0), s.thermal.c1);
        assert!((t.outputs.t_fc1_nm - tq).abs() <= 1e-9 * tq.abs().max(1.0));
    }
    assert!(
        closing > 100 && opening > 50,
        "closing {closing} opening {opening}"
    );
    // Measured on the way up, the same sensor position gives less torque than nominal.
    let i = (0..a.truth.len())
        .find(|&i| n.truth[i].outputs.t_fc1_nm > 30.0)
        .unwrap();
    assert!(a.truth[i].outputs.t_fc1_nm < n.truth[i].outputs.t_fc1_nm - 2.0);
}

#[test]
fn dead_time_shifts_actuator_and_torque_in_time_not_in_value() {
    let d = 0.02;
    let a = run(
        rig_config(single(EffectId::ActuatorDeadTime, &[d]), 25.0),
        2.2,
    );
    let n = run(rig_config(EffectSet::nominal(), 25.0), 2.2);
    let shift = 20;
    for i in shift..a.truth.len() {
        // The actuator (what the sensor measures) is the nominal one 20 ms later.
        assert!((a.truth[i].state.x1_mm - n.truth[i - shift].state.x1_mm).abs() < 1e-12);
        assert_eq!(
            a.truth[i].x_ref_applied_mm[0],
            n.truth[i - shift].x_ref_applied_mm[0]
        );
        assert_eq!(
            a.truth[i].x_ref_mm, n.truth[i].x_ref_mm,
            "the command itself is not delayed"
        );
    }
    // Torque: the same values 20 ms later (up to the slightly shifted heating).
    let mut worst: f64 = 0.0;
    for i in shift..a.truth.len() {
        let (x, y) = (
            a.truth[i].outputs.t_fc1_nm,
            n.truth[i - shift].outputs.t_fc1_nm,
        );
        if y > 5.0 {
            worst = worst.max(rel(x, y));
        }
    }
    assert!(worst < 2e-3, "worst relative torque difference {worst}");
    // And not at the same instant during the ramp.
    let i = (0..n.truth.len())
        .find(|&i| n.truth[i].outputs.t_fc1_nm > 30.0)
        .unwrap();
    assert!(a.truth[i].outputs.t_fc1_nm < 0.97 * n.truth[i].outputs.t_fc1_nm);
}

/// Vehicle-mode plant with a TCU stand-in feeding TCU_EngineReq / TCU_ClutchCmd / TCU_GearCmd.
fn vehicle_config(effects: EffectSet) -> PlantConfig {
    let mut c = PlantConfig::default();
    c.sensors = SensorNoise::default();
    c.effects = effects;
    c.scenario = None;
    c
}

fn protected(id: u16, data: [u8; 8], counter: u8) -> CanFrame {
    let mut d = data;
    ddct::can::e2e::protect(id, &mut d, counter);
    CanFrame::standard(id, &d).unwrap()
}

fn rx_at(t: Duration, frame: CanFrame) -> Received {
    Received {
        frame,
        timestamp: t,
    }
}

fn engine_request_frames(k: u64, torque: f64) -> Vec<Received> {
    if k % 10 != 0 {
        return vec![];
    }
    let c = ((k / 10) % 16) as u8;
    let t = MS * k as u32;
    let req = TcuEngineReq {
        eng_torque_req: torque,
        eng_torque_req_active: true,
        ..Default::default()
    };
    vec![rx_at(
        t,
        protected(ids::TCU_ENGINE_REQ, req.encode().unwrap(), c),
    )]
}

#[test]
fn engine_torque_error_changes_real_torque_while_ecu_reports_the_map() {
    let e = -0.08;
    let a = run_with(
        vehicle_config(single(EffectId::EngineTorqueError, &[e])),
        1.0,
        |k| engine_request_frames(k, 60.0),
    );
    let n = run_with(vehicle_config(EffectSet::nominal()), 1.0, |k| {
        engine_request_frames(k, 60.0)
    });
    let last = a.truth.last().unwrap();
    // Real torque (1 + e)·request after the 50 ms lag; the ECU reports its map value.
    assert!(
        (last.state.engine_torque_nm - 60.0 * (1.0 + e)).abs() < 1e-3,
        "{}",
        last.state.engine_torque_nm
    );
    assert!((last.engine_torque_reported_nm - 60.0).abs() < 1e-3);
    let eng = |r: &Run| {
        frames_of(r, ids::ENG_STATUS)
            .last()
            .map(|f| EngStatus::decode(f.frame.bytes()).unwrap())
            .unwrap()
    };
    assert!((eng(&a).eng_torque_act - 60.0).abs() <= 0.05);
    assert!((eng(&n).eng_torque_act - 60.0).abs() <= 0.05);
    // The real torque acts: the free engine accelerates less than with the nominal map.
    let (w0, wa, wn) = (
        a.truth[0].state.w_f,
        last.state.w_f,
        n.truth.last().unwrap().state.w_f,
    );
    assert!(wa < wn);
    // Free engine: J·Δω = ∫T dt, so the speed gains are in the ratio of the real torques.
    let ratio = (wa - w0) / (wn - w0);
    assert!((ratio - (1.0 + e)).abs() < 0.01, "speed-gain ratio {ratio}");
    // Nothing else: clutches, thermal masses and gears are untouched.
    assert_eq!(last.state.thermal, n.truth.last().unwrap().state.thermal);
    assert_eq!(last.state.x1_mm, 0.0);
}

#[test]
fn kiss_point_wear_shifts_the_characteristic_with_friction_energy() {
    let kw = 2.0;
    let r = run(
        rig_config(single(EffectId::KissPointWear, &[kw]), 25.0),
        5.2,
    );
    let n = run(rig_config(EffectSet::nominal(), 25.0), 5.2);
    let p = hot_params();
    let mut m = 0;
    for i in 1..r.truth.len() {
        let t = &r.truth[i];
        let s = &t.state;
        if t.outputs.t_fc1_nm <= 1.0 {
            continue;
        }
        // (7)–(9) shifted by k_w·E (the energy of the state the torque is evaluated at).
        let expect = clutch::torque(
            &p,
            s.x1_mm - kw * s.e_fric1_j * 1e-6,
            s.slip(0),
            s.thermal.c1,
        );
        assert!(
            rel(t.outputs.t_fc1_nm, expect) < 1e-9,
            "{} vs {expect}",
            t.outputs.t_fc1_nm
        );
        // The clutch opens (β = 0) at the shifted kiss point.
        let open = s.x1_mm - kw * s.e_fric1_j * 1e-6 <= clutch::x_isp(&p, s.thermal.c1);
        assert_eq!(t.outputs.beta1 == 0.0, open);
        m += 1;
    }
    assert!(m > 1000);
    // Before any friction energy the clutch is the nominal one; after ~30 kJ the second
    // engagement starts transmitting later by k_w·E.
    let first = (0..n.truth.len())
        .find(|&i| n.truth[i].outputs.t_fc1_nm > 0.0)
        .unwrap();
    assert!(
        rel(
            r.truth[first].outputs.t_fc1_nm,
            n.truth[first].outputs.t_fc1_nm
        ) < 1e-4
    );
    let e_after_first = r.truth[3000].state.e_fric1_j;
    assert!(e_after_first > 10e3);
    let second = |run: &Run| {
        (3000..run.truth.len())
            .find(|&i| run.truth[i].outputs.t_fc1_nm > 0.0)
            .unwrap()
    };
    let shift_mm = kw * e_after_first * 1e-6;
    let ramp_mm_per_ms = 2.1 / 1000.0;
    let lag = second(&r) as f64 - second(&n) as f64;
    assert!(
        (lag - shift_mm / ramp_mm_per_ms).abs() <= 3.0,
        "lag {lag} ms, expected {}",
        shift_mm / ramp_mm_per_ms
    );
}

#[test]
fn surface_temperature_friction_follows_its_fast_state() {
    let (h, tau) = (0.01, 0.4);
    let r = run(
        rig_config(
            single(EffectId::SurfaceTemperatureFriction, &[h, tau]),
            40.0,
        ),
        3.4,
    );
    let p = hot_params();
    let mut theta_s = 40.0;
    let mut n = 0;
    for i in 1..r.truth.len() {
        let t = &r.truth[i];
        let s = &t.state;
        // The torque of step i used the surface temperature at its start: μ_d at θ_s on both
        // facings, the spring at θ_c.
        if t.outputs.t_fc1_nm > 1.0 {
            let expect =
                clutch::torque_two_facing(&p, s.x1_mm, s.slip(0), theta_s, theta_s, s.thermal.c1);
            assert!(
                rel(t.outputs.t_fc1_nm, expect) < 1e-9,
                "{} vs {expect}",
                t.outputs.t_fc1_nm
            );
            n += 1;
        }
        // Exact solution over the step with the power and θ_c at its end held.
        let eq = s.thermal.c1 + h * t.outputs.p_fric1_w * tau;
        theta_s = eq + (theta_s - eq) * (-1e-3 / tau).exp();
        assert!((t.theta_surface_c[0] - theta_s).abs() < 1e-9);
    }
    assert!(n > 500);
    // Flash temperature well above the disk while slipping, back to θ_c when open.
    let peak = r
        .truth
        .iter()
        .map(|t| t.theta_surface_c[0] - t.state.thermal.c1)
        .fold(0.0, f64::max);
    assert!(peak > 20.0, "flash {peak}");
    let last = r.truth.last().unwrap();
    // 1.2 s = 3 τ after the release at 2.2 s: below e^-3 ≈ 5 % of the flash (+ θ_c's drift).
    assert!(
        (last.theta_surface_c[0] - last.state.thermal.c1).abs() < 0.06 * peak,
        "{peak}"
    );
    assert!(!EffectId::SurfaceTemperatureFriction.in_library());
}

#[test]
fn sliding_acceleration_friction_acts_only_while_the_slip_accelerates() {
    let (g, a_ref) = (0.15, 1.0);
    // Vehicle launch: gear 1, clutch 1 closed by the test at 6 mm, engine request 120 N·m.
    let frames = |k: u64| -> Vec<Received> {
        if k % 10 != 0 {
            return vec![];
        }
        let c = ((k / 10) % 16) as u8;
        let t = MS * k as u32;
        let x = if k < 200 { 0.0 } else { 5.6 };
        let cmd = TcuClutchCmd {
            clutch1_pos_req: x,
            ..Default::default()
        };
        let gear = TcuGearCmd {
            gear_odd_req: ddct::can::messages::GearOddReq::G1,
            ..Default::default()
        };
        let mut v = engine_request_frames(k, 120.0);
        v.push(rx_at(
            t,
            protected(ids::TCU_CLUTCH_CMD, cmd.encode().unwrap(), c),
        ));
        v.push(rx_at(
            t,
            protected(ids::TCU_GEAR_CMD, gear.encode().unwrap(), c),
        ));
        v
    };
    let mut cfg = vehicle_config(single(EffectId::SlidingAccelerationFriction, &[g, a_ref]));
    cfg.initial.engine_rpm = 2000.0;
    cfg.initial.gear_odd = Gear::G1;
    let r = run_with(cfg, 1.5, frames);
    let p = hot_params();
    let r_m = 0.5 * (p.r1_m + p.r2_m);
    let mut changed = 0;
    let mut n = 0;
    for i in 1..r.truth.len() {
        let t = &r.truth[i];
        let s = &t.state;
        if t.state.lock1 || t.outputs.t_fc1_nm.abs() <= 1.0 {
            continue;
        }
        let prev = &r.truth[i - 1].outputs;
        let slip_acc = prev.acc[0] - prev.acc[1];
        let factor = 1.0 + g * (-(r_m * s.slip(0).signum() * slip_acc) / a_ref).tanh();
        let expect = clutch::torque(&p, s.x1_mm, s.slip(0), s.thermal.c1) * factor;
        assert!(
            rel(t.outputs.t_fc1_nm, expect) < 1e-9,
            "{} vs {expect}",
            t.outputs.t_fc1_nm
        );
        if (factor - 1.0).abs() > 0.01 {
            changed += 1;
        }
        n += 1;
    }
    assert!(n > 100 && changed > 50, "n {n} changed {changed}");
    assert!(!EffectId::SlidingAccelerationFriction.in_library());
}

// -------------------------------------------------------------------------------------- faults

/// Vehicle mode with the built-in driver (so DRV_Pedal is sent too), noise on.
fn fault_config(kind: &str, extra: &str, message: &str) -> PlantConfig {
    let text = format!(
        "[plant]\nscenario = \"scenarios/driver_launch.toml\"\n[sensors]\nspeed_rpm = 0.5\ntorque_nm = 0.3\n\
         [[faults]]\nmessage = \"{message}\"\nkind = \"{kind}\"\nfrom_s = 0.5\nto_s = 0.8\n{extra}\n"
    );
    PlantConfig::from_toml_str(
        Path::new("config/fault_test.toml"),
        &text,
        Some(Path::new("config/fault_test.toml")),
    )
    .unwrap()
}

fn clean_config() -> PlantConfig {
    fault_config("drop", "", "SIM_Truth").tap_no_faults()
}

trait NoFaults {
    fn tap_no_faults(self) -> Self;
}
impl NoFaults for PlantConfig {
    fn tap_no_faults(mut self) -> Self {
        self.faults.clear();
        self
    }
}

/// The cycle a frame belongs to (its due time minus any configured delay is a multiple of 10 ms).
fn cycle_time(f: &OutFrame) -> Duration {
    let ms = f.due.as_millis() as u64;
    Duration::from_millis(ms - ms % 10)
}

/// Frames per message of a run: (cycle ms, frame) in order.
fn per_cycle(r: &Run, id: u16) -> Vec<(u64, OutFrame)> {
    frames_of(r, id)
        .into_iter()
        .map(|f| (cycle_time(f).as_millis() as u64, *f))
        .collect()
}

#[test]
fn fault_drop_loses_frames_in_the_window_only() {
    let clean = run(clean_config(), 1.2);
    let r = run(fault_config("drop", "", "DCT_Sensors"), 1.2);
    let a = per_cycle(&r, ids::DCT_SENSORS);
    let b = per_cycle(&clean, ids::DCT_SENSORS);
    let expected: Vec<_> = b.iter().filter(|(c, _)| !(500..800).contains(c)).collect();
    assert_eq!(a.len(), expected.len());
    assert_eq!(b.len() - a.len(), 30);
    for ((ca, fa), (cb, fb)) in a.iter().zip(expected) {
        // Outside the window the frames are the clean ones (the counter kept counting).
        assert_eq!((ca, fa.frame), (cb, fb.frame));
    }
    // Other messages are untouched.
    assert_eq!(
        per_cycle(&r, ids::ENG_STATUS).len(),
        per_cycle(&clean, ids::ENG_STATUS).len()
    );
    assert_eq!(
        frames_of(&r, ids::DCT_SENSORS)
            .iter()
            .filter(|f| f.fault.is_some())
            .count(),
        0
    );
    // every = 2: every other frame of the window.
    let r2 = run(fault_config("drop", "every = 2", "DCT_Sensors"), 1.2);
    assert_eq!(b.len() - per_cycle(&r2, ids::DCT_SENSORS).len(), 15);
}

#[test]
fn fault_delay_sends_window_frames_late_only() {
    let clean = run(clean_config(), 1.2);
    let r = run(fault_config("delay", "delay_ms = 25", "ENG_Status"), 1.2);
    let a = frames_of(&r, ids::ENG_STATUS);
    let b = frames_of(&clean, ids::ENG_STATUS);
    assert_eq!(a.len(), b.len());
    let mut delayed = 0;
    for fa in &a {
        // Each frame is the clean frame of its cycle, sent 25 ms late inside the window.
        let late = fa.fault == Some(FaultKind::Delay);
        let cycle = if late {
            fa.due - Duration::from_millis(25)
        } else {
            fa.due
        };
        let fb = b.iter().find(|fb| fb.due == cycle).unwrap();
        assert_eq!(fa.frame, fb.frame);
        if cycle >= Duration::from_millis(500) && cycle < Duration::from_millis(800) {
            assert_eq!(fa.due, cycle + Duration::from_millis(25));
            assert_eq!(fa.fault, Some(FaultKind::Delay));
            delayed += 1;
        } else {
            assert_eq!(fa.due, cycle);
            assert_eq!(fa.fault, None);
        }
    }
    assert_eq!(delayed, 30);
    // As a receiver sees them: the last delayed frames come after newer ones.
    let order: Vec<u64> = a
        .iter()
        .map(|f| {
            let late = f.fault == Some(FaultKind::Delay);
            (f.due.as_millis() - if late { 25 } else { 0 }) as u64
        })
        .collect();
    let pos = |c: u64| order.iter().position(|&x| x == c).unwrap();
    assert!(pos(800) < pos(790) && pos(780) < pos(790));
    // Other messages keep their timing.
    assert!(frames_of(&r, ids::DCT_SENSORS)
        .iter()
        .all(|f| f.due.as_millis() % 10 == 0));
}

#[test]
fn fault_freeze_counter_repeats_the_counter_in_the_window_only() {
    let r = run(fault_config("freeze_counter", "", "DCT_Actuators"), 1.2);
    let f = per_cycle(&r, ids::DCT_ACTUATORS);
    let mut last: Option<u8> = None;
    for (c, f) in &f {
        let d: [u8; 8] = f.frame.bytes().try_into().unwrap();
        assert_eq!(
            d[CRC_BYTE],
            e2e_crc(ids::DCT_ACTUATORS, &d),
            "CRC stays valid"
        );
        let ctr = counter_of(&d);
        if let Some(p) = last {
            if (500..800).contains(c) {
                assert_eq!(ctr, p, "frozen at {c} ms");
            } else {
                assert_eq!(ctr, (p + 1) % 16, "counting at {c} ms");
            }
        }
        last = Some(ctr);
    }
    assert_eq!(f.len(), 121);
}

#[test]
fn fault_corrupt_crc_breaks_the_crc_in_the_window_only() {
    let clean = run(clean_config(), 1.2);
    let r = run(fault_config("corrupt_crc", "", "ENG_Status"), 1.2);
    let a = per_cycle(&r, ids::ENG_STATUS);
    let b = per_cycle(&clean, ids::ENG_STATUS);
    assert_eq!(a.len(), b.len());
    for ((c, fa), (_, fb)) in a.iter().zip(&b) {
        let d: [u8; 8] = fa.frame.bytes().try_into().unwrap();
        let ok = d[CRC_BYTE] == e2e_crc(ids::ENG_STATUS, &d);
        assert_eq!(ok, !(500..800).contains(c), "{c} ms");
        assert_eq!(fa.frame.bytes()[..CRC_BYTE], fb.frame.bytes()[..CRC_BYTE]);
    }
}

#[test]
fn fault_stop_silences_the_sender_in_the_window_only() {
    let r = run(fault_config("stop", "", "DRV_Pedal"), 1.2);
    let f = per_cycle(&r, ids::DRV_PEDAL);
    assert_eq!(f.len(), 121 - 30);
    assert!(f.iter().all(|(c, _)| !(500..800).contains(c)));
    // The counter did not advance while silent: consecutive across the gap.
    let ctr: Vec<u8> = f
        .iter()
        .map(|(_, f)| counter_of(&f.frame.bytes().try_into().unwrap()))
        .collect();
    for w in ctr.windows(2) {
        assert_eq!(w[1], (w[0] + 1) % 16);
    }
    // Only DRV_Pedal stopped.
    assert_eq!(per_cycle(&r, ids::ENG_STATUS).len(), 121);
}

#[test]
fn fault_implausible_value_with_valid_protection_in_the_window_only() {
    let clean = run(clean_config(), 1.2);
    let r = run(
        fault_config(
            "implausible",
            "signal = \"EngSpeed\"\nvalue = 9000.0",
            "ENG_Status",
        ),
        1.2,
    );
    let a = per_cycle(&r, ids::ENG_STATUS);
    let b = per_cycle(&clean, ids::ENG_STATUS);
    for ((c, fa), (_, fb)) in a.iter().zip(&b) {
        let d: [u8; 8] = fa.frame.bytes().try_into().unwrap();
        assert_eq!(d[CRC_BYTE], e2e_crc(ids::ENG_STATUS, &d));
        let m = EngStatus::decode(&d).unwrap();
        let clean_m = EngStatus::decode(fb.frame.bytes()).unwrap();
        if (500..800).contains(c) {
            assert_eq!(m.eng_speed, 9000.0);
            assert_eq!(m.eng_torque_act, clean_m.eng_torque_act);
        } else {
            assert_eq!(fa.frame, fb.frame);
        }
    }
    // A value outside the DBC range is sent saturated to the signal's bits: the receiver's
    // decoder flags it.
    let r = run(
        fault_config(
            "implausible",
            "signal = \"EngSpeed\"\nvalue = 20000.0",
            "ENG_Status",
        ),
        1.2,
    );
    let bad = per_cycle(&r, ids::ENG_STATUS)
        .into_iter()
        .filter(|(_, f)| EngStatus::decode(f.frame.bytes()).is_err())
        .map(|(c, _)| c)
        .collect::<Vec<_>>();
    assert_eq!(bad, (500..800).step_by(10).collect::<Vec<u64>>());
}

// ------------------------------------------------------------------------------------- energy

#[test]
fn friction_energy_equals_heat_taken_by_the_thermal_model() {
    // A rig run of two engagements and cooling. ∫T·ω dt from the 1 ms truth (trapezoid) against
    // the heat each thermal mass of (16) took: its temperature change minus the integrated
    // exchange terms, divided by its α weighting.
    let r = run(rig_config(EffectSet::nominal(), 25.0), 7.2);
    let a = ddct::model::Params::default().thermal5;
    let dt = 1e-3;
    let mut e = 0.0;
    let (mut x_pp1, mut x_c1, mut x_cd) = (0.0, 0.0, 0.0);
    let exch = |t: &Truth| {
        let s = &t.state.thermal;
        let (b1, b2, h) = (t.outputs.beta1, t.outputs.beta2, t.theta_h_c);
        (
            a.alpha1_per_s * b1 * (s.c1 - s.pp1) + a.alpha2_per_s * (1.0 - b1) * (h - s.pp1),
            a.alpha4_per_s * b1 * (s.pp1 - s.c1)
                + a.alpha5_per_s * b1 * (s.cd - s.c1)
                + a.alpha6_per_s * (1.0 - b1) * (h - s.c1),
            a.alpha5_per_s * b1 * (s.c1 - s.cd)
                + a.alpha5_per_s * b2 * (s.c2 - s.cd)
                + a.alpha8_per_s * (2.0 - b1 - b2) * (h - s.cd),
        )
    };
    for w in r.truth.windows(2) {
        let p = |t: &Truth| {
            t.outputs.t_fc1_nm * t.outputs.slip1_radps + t.outputs.t_fc2_nm * t.outputs.slip2_radps
        };
        e += 0.5 * (p(&w[0]) + p(&w[1])) * dt;
        let (e0, e1) = (exch(&w[0]), exch(&w[1]));
        x_pp1 += 0.5 * (e0.0 + e1.0) * dt;
        x_c1 += 0.5 * (e0.1 + e1.1) * dt;
        x_cd += 0.5 * (e0.2 + e1.2) * dt;
    }
    let (s0, s1) = (
        &r.truth[0].state.thermal,
        &r.truth.last().unwrap().state.thermal,
    );
    let heat = [
        (
            "pressure plate",
            (s1.pp1 - s0.pp1 - x_pp1) / a.alpha3_k_per_j,
        ),
        ("clutch disk", (s1.c1 - s0.c1 - x_c1) / a.alpha7_k_per_j),
        ("central disk", (s1.cd - s0.cd - x_cd) / a.alpha9_k_per_j),
    ];
    println!("friction energy {e:.1} J; heat taken {heat:?}");
    assert!(e > 10e3, "{e}");
    for (name, q) in heat {
        assert!(rel(q, e) < 1e-3, "{name}: {q} J vs {e} J");
    }
    // The plant's own book-keeping agrees too.
    let last = r.truth.last().unwrap();
    assert!(rel(last.state.e_fric1_j + last.state.e_fric2_j, e) < 1e-3);
}

// -------------------------------------------------------------------------- rig experiment

#[test]
fn rig_identification_experiment_reproduces_fig6_in_process() {
    // The identification profile in process, evaluated on the decoded frames only.
    let mut cfg = PlantConfig::load(Path::new("config/plant_rig.toml")).unwrap();
    let prof = RigProfile::load(Path::new("config/rig/identification.toml")).unwrap();
    cfg.rig_profile = Some(prof.clone());
    let mut p = Plant::new(cfg);
    let cycles = (prof.duration_s() * 100.0).round() as u64;
    let mut peak = vec![0.0f64; prof.count as usize];
    let mut cd_max = vec![f64::MIN; prof.count as usize];
    let mut speed = Vec::new();
    for k in 0..=cycles {
        let out = p.step(Duration::from_millis(10 * k), &[]);
        for f in out.frames {
            let t = f.due.as_secs_f64();
            let Some(e) = prof.engagement_at(t) else {
                continue;
            };
            let e = e as usize;
            match f.frame.standard_id() {
                Some(ids::BENCH_TORQUE) => {
                    peak[e] =
                        peak[e].max(BenchTorque::decode(f.frame.bytes()).unwrap().clutch1_torque)
                }
                Some(ids::BENCH_TEMPS) => {
                    cd_max[e] = cd_max[e].max(
                        BenchTemps::decode(f.frame.bytes())
                            .unwrap()
                            .central_disk_temp,
                    )
                }
                Some(ids::ENG_STATUS) => {
                    speed.push(EngStatus::decode(f.frame.bytes()).unwrap().eng_speed)
                }
                _ => {}
            }
        }
    }
    let hot = cd_max
        .iter()
        .position(|&c| c > 200.0)
        .expect("the central disk passes 200 °C");
    println!(
        "first engagement peak {:.1} N·m; engagement {hot} (cd {:.1} °C) peak {:.1} N·m",
        peak[0], cd_max[hot], peak[hot]
    );
    assert!(peak[0] > 20.0);
    assert!(peak[hot] >= 1.5 * peak[0]);
    // The torque grows monotonically with the temperature over the engagements (same x_to).
    assert!(peak.windows(2).all(|w| w[1] >= w[0] - 1.0));
    // The dyno holds the input speed (within sensor noise and quantisation).
    assert!(speed.iter().all(|v| (v - prof.input_speed_rpm).abs() < 4.0));
}

// --------------------------------------------------------------------- sensors and inputs

#[test]
fn sensors_quantise_to_the_contract_without_noise() {
    let mut cfg = rig_config(EffectSet::nominal(), 25.0);
    cfg.sensors = SensorNoise::default();
    let r = run(cfg, 1.5);
    for f in frames_of(&r, ids::BENCH_TORQUE) {
        let k = f.due.as_millis() as usize;
        let m = BenchTorque::decode(f.frame.bytes()).unwrap();
        let truth = r.truth[k].outputs.t_fc1_nm;
        assert!(
            (m.clutch1_torque - truth).abs() <= 0.05 + 1e-9,
            "{} vs {truth}",
            m.clutch1_torque
        );
        assert!((m.clutch1_torque * 10.0 - (m.clutch1_torque * 10.0).round()).abs() < 1e-6);
    }
    for f in frames_of(&r, ids::DCT_ACTUATORS) {
        let k = f.due.as_millis() as usize;
        let m = DctActuators::decode(f.frame.bytes()).unwrap();
        assert!((m.clutch1_pos - r.truth[k].state.x1_mm).abs() <= 0.0005 + 1e-9);
    }
}

#[test]
fn sensor_noise_is_seeded_and_has_the_configured_spread() {
    let noisy = |seed: u64| {
        let mut c = rig_config(EffectSet::nominal(), 25.0);
        c.rig_profile = None;
        c.sensors.temperature_c = 0.5;
        c.seed = seed;
        run(c, 20.0)
    };
    let (a, b, c) = (noisy(7), noisy(7), noisy(8));
    assert_eq!(a.frames, b.frames, "same seed, same frames");
    assert_ne!(a.frames, c.frames);
    // Thermocouple readings at a constant 25 °C: mean 25, standard deviation 0.5 (quantised to
    // 0.1 °C: + 0.1²/12), over 2001 cycles.
    let v: Vec<f64> = frames_of(&a, ids::BENCH_TEMPS)
        .iter()
        .map(|f| {
            BenchTemps::decode(f.frame.bytes())
                .unwrap()
                .central_disk_temp
        })
        .collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!((mean - 25.0).abs() < 0.05, "mean {mean}");
    assert!(
        (sd - (0.25f64 + 0.01 / 12.0).sqrt()).abs() < 0.04,
        "sd {sd}"
    );
}

#[test]
fn housing_air_relaxes_to_its_target() {
    let mut c = rig_config(EffectSet::nominal(), 25.0);
    c.rig_profile = None;
    c.initial.housing_c = 20.0;
    c.housing.target_c = 60.0;
    c.housing.tau_s = 50.0;
    let r = run(c, 100.0);
    for i in [10_000usize, 50_000, 100_000] {
        let t = i as f64 * 1e-3;
        let expect = 60.0 - 40.0 * (-t / 50.0).exp();
        assert!((r.truth[i].theta_h_c - expect).abs() < 1e-9);
    }
    let last = frames_of(&r, ids::DCT_SENSORS)
        .last()
        .map(|f| DctSensors::decode(f.frame.bytes()).unwrap())
        .unwrap();
    assert_eq!(last.housing_temp, (60.0 - 40.0 * (-2.0f64).exp()).round());
}

fn clutch_cmd(k_cycle: u64, x: f64) -> CanFrame {
    let m = TcuClutchCmd {
        clutch1_pos_req: x,
        ..Default::default()
    };
    protected(
        ids::TCU_CLUTCH_CMD,
        m.encode().unwrap(),
        (k_cycle % 16) as u8,
    )
}

#[test]
fn commands_act_from_the_next_cycle_and_time_out_to_open() {
    // Rig mode over the bus (no built-in profile): a command stamped 3 ms after cycle 10 acts
    // from cycle 11 on; after the last command the request falls to 0 mm once 50 cycles passed.
    let mut cfg = rig_config(EffectSet::nominal(), 25.0);
    cfg.rig_profile = None;
    let mut p = Plant::new(cfg);
    let mut x_ref_at = Vec::new();
    for k in 0..=2000u64 {
        let mut rx = vec![];
        if k % 10 == 3 && (100..600).contains(&k) {
            rx.push(rx_at(MS * k as u32, clutch_cmd(k / 10, 4.0)));
        }
        let out = p.step(MS * k as u32, &rx);
        x_ref_at.push(out.truth.x_ref_mm[0]);
    }
    // x_ref_at[k] is the request of the step from k−1 to k ms.
    assert_eq!(x_ref_at[110], 0.0);
    assert_eq!(x_ref_at[111], 4.0, "latched at the 110 ms boundary");
    // Last command at 593 ms: fresh until 593 + 500 ms.
    assert_eq!(x_ref_at[1093], 4.0);
    assert_eq!(x_ref_at[1094], 0.0);
    assert_eq!(p.stats().input_timeouts.get("TCU_ClutchCmd"), Some(&1));
}

#[test]
fn bad_input_frames_are_counted_and_ignored_never_panic() {
    let mut cfg = vehicle_config(EffectSet::nominal());
    cfg.inputs.timeout_cycles = 1000;
    let mut p = Plant::new(cfg);
    let t = |k: u32| MS * k;
    let good = clutch_cmd(0, 3.0);
    p.step(t(10), &[rx_at(t(5), good)]);
    assert_eq!(p.step(t(20), &[]).truth.x_ref_mm[0], 3.0);
    let mut bad_crc: [u8; 8] = clutch_cmd(1, 6.0).bytes().try_into().unwrap();
    bad_crc[CRC_BYTE] ^= 1;
    let out_of_range = {
        // Clutch1PosReq raw 9000 = 9 mm > the DBC's 8 mm.
        let mut raw = 0u64;
        message_def(u32::from(ids::TCU_CLUTCH_CMD)).unwrap().signals[0].insert(&mut raw, 9000);
        protected(ids::TCU_CLUTCH_CMD, raw.to_le_bytes(), 1)
    };
    let frames = [
        CanFrame::standard(ids::TCU_CLUTCH_CMD, &bad_crc).unwrap(),
        CanFrame::standard(ids::TCU_CLUTCH_CMD, &[1, 2, 3]).unwrap(),
        clutch_cmd(0, 6.0), // repeated counter
        out_of_range,
        CanFrame::extended(0x1234, &[0; 8]).unwrap(),
        CanFrame::standard(0x7FF, &[0xFF; 8]).unwrap(),
        CanFrame::standard(ids::TCU_STATUS, &[0; 8]).unwrap(),
    ];
    let rx: Vec<Received> = frames.iter().map(|f| rx_at(t(25), *f)).collect();
    let out = p.step(t(40), &rx);
    assert_eq!(
        out.truth.x_ref_mm[0], 3.0,
        "no bad frame changed the command"
    );
    let e = &p.stats().rx_errors;
    assert_eq!(e.get("TCU_ClutchCmd.bad_crc"), Some(&1));
    assert_eq!(e.get("TCU_ClutchCmd.wrong_dlc"), Some(&1));
    assert_eq!(e.get("TCU_ClutchCmd.counter_repeated"), Some(&1));
    assert_eq!(e.get("TCU_ClutchCmd.decode"), Some(&1));
    assert_eq!(p.stats().rx_ignored, 3);
    // A skipped counter still carries valid data: accepted, and counted.
    let out = p.step(t(60), &[rx_at(t(45), clutch_cmd(5, 5.0))]);
    assert_eq!(out.truth.x_ref_mm[0], 5.0);
    assert_eq!(
        p.stats().rx_errors.get("TCU_ClutchCmd.counter_skipped"),
        Some(&1)
    );
    // A second driver on the bus while the plant plays the driver is reported.
    let mut p = Plant::new(PlantConfig {
        scenario: Some(ddct::plant::Scenario::builtin()),
        ..vehicle_config(EffectSet::nominal())
    });
    let pedal = protected(ids::DRV_PEDAL, DrvPedal::default().encode().unwrap(), 0);
    p.step(t(20), &[rx_at(t(5), pedal)]);
    assert_eq!(p.stats().rx_errors.get("DRV_Pedal.second_driver"), Some(&1));
}

#[test]
fn vehicle_mode_with_the_builtin_driver() {
    let mut cfg = PlantConfig::default();
    cfg.scenario = Some(ddct::plant::Scenario::builtin());
    let r = run(cfg, 4.0);
    let sc = ddct::plant::Scenario::builtin();
    // DRV_Pedal carries the scenario's pedal and lever.
    for f in frames_of(&r, ids::DRV_PEDAL) {
        let m = DrvPedal::decode(f.frame.bytes()).unwrap();
        let d = sc.sample(f.due.as_secs_f64());
        assert!((m.accel_pedal - d.pedal * 100.0).abs() <= 0.05 + 1e-9);
        assert_eq!(m.gear_lever, d.lever);
        assert_eq!(m.brake_switch, d.brake > 0.0);
    }
    // No TCU: clutches open; the engine idles at ~800 rpm and revs up with the pedal.
    assert!((r.truth[1900].state.w_f / RPM - 800.0).abs() < 30.0);
    assert!(r.truth[4000].state.w_f / RPM > 2000.0);
    assert!(r
        .truth
        .iter()
        .all(|t| t.state.x1_mm == 0.0 && t.state.w_out.abs() < 1e-9));
    // Every message every 10 ms.
    for id in [
        ids::DRV_PEDAL,
        ids::ENG_STATUS,
        ids::DCT_SENSORS,
        ids::DCT_ACTUATORS,
        ids::BENCH_TORQUE,
        ids::BENCH_TEMPS,
        ids::BENCH_VEHICLE,
        ids::SIM_TRUTH,
    ] {
        let f = frames_of(&r, id);
        assert_eq!(f.len(), 401, "{:#x}", id);
        assert!(f
            .windows(2)
            .all(|w| w[1].due - w[0].due == Duration::from_millis(10)));
    }
}

#[test]
fn initial_conditions_are_applied() {
    let mut cfg = PlantConfig::default();
    cfg.sensors = SensorNoise::default();
    cfg.initial.vehicle_kmh = 50.0;
    cfg.initial.gear_odd = Gear::G3;
    cfg.initial.engine_rpm = 1500.0;
    cfg.initial.c1_c = Some(180.0);
    cfg.initial.cd_c = Some(120.0);
    let p = Plant::new(cfg.clone());
    let s = p.state();
    let pd = &cfg.params.driveline;
    assert!((s.w_out * pd.wheel_radius_m * 3.6 - 50.0).abs() < 1e-9);
    assert!((s.w_c1 - pd.ratio_g3 * pd.final_drive * s.w_out).abs() < 1e-9);
    assert_eq!(s.gear_odd.engaged, Gear::G3);
    assert_eq!(
        (s.thermal.c1, s.thermal.cd, s.thermal.pp1),
        (180.0, 120.0, 25.0)
    );
    assert!((s.w_f / RPM - 1500.0).abs() < 1e-9);
    assert_eq!(cfg.mode, Mode::Vehicle);
}

// ------------------------------------------------------------------------------------ daemon

#[tokio::test]
async fn daemon_virtual_run_sends_every_cycle_and_logs_it() {
    use ddct::daemon::plant::{run as run_plant, Pacing, PlantDaemonConfig};
    let clock = Arc::new(ManualClock::new(Duration::from_secs(1_000_000)));
    let bus = InProcessBus::with_clock("sim", clock.clone());
    let plant_ep = bus.endpoint(EndpointConfig::default());
    let mut observer = bus.endpoint(EndpointConfig {
        own_echo: false,
        queue: 1 << 16,
    });
    let dir = std::env::temp_dir().join(format!("ddct-plant-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("virtual.log");
    let cfg = PlantDaemonConfig {
        plant: rig_config(EffectSet::nominal(), 25.0),
        pacing: Pacing::Virtual { clock: Some(clock) },
        duration: Some(Duration::from_secs(2)),
        log: Some(log.clone()),
        lockstep: None,
    };
    let report = run_plant(plant_ep, std::future::pending::<()>(), cfg)
        .await
        .unwrap();
    assert_eq!(report.stopped_by, "duration");
    assert_eq!(report.frames_sent, 201 * 7);
    let mut got = 0;
    let mut last_t = Duration::ZERO;
    while let Ok(Some(r)) = observer.try_recv() {
        assert!(
            r.timestamp >= last_t,
            "the bus clock follows simulated time"
        );
        last_t = r.timestamp;
        got += 1;
    }
    assert_eq!(got, 201 * 7);
    assert_eq!(last_t, Duration::from_secs(1_000_002));
    let lines = std::fs::read_to_string(&log).unwrap().lines().count();
    assert_eq!(lines as u64, report.frames_sent);
    std::fs::remove_dir_all(&dir).ok();
}

#[tokio::test]
async fn daemon_real_time_stops_on_shutdown_and_flushes_its_log() {
    use ddct::daemon::plant::{run as run_plant, Pacing, PlantDaemonConfig};
    let bus = InProcessBus::new("rt");
    let plant_ep = bus.endpoint(EndpointConfig::default());
    let mut driver = bus.endpoint(EndpointConfig::default());
    let dir = std::env::temp_dir().join(format!("ddct-plant-rt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("rt.log");
    let mut cfg = rig_config(EffectSet::nominal(), 25.0);
    cfg.rig_profile = None;
    let cfg = PlantDaemonConfig {
        plant: cfg,
        pacing: Pacing::RealTime { speed: 1.0 },
        duration: None,
        log: Some(log.clone()),
        lockstep: None,
    };
    // A controller stand-in: a few clutch commands, then the shutdown.
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let ctl = tokio::spawn(async move {
        for k in 0..20u64 {
            driver.send(clutch_cmd(k, 4.0)).await.unwrap();
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        tokio::time::sleep(Duration::from_millis(60)).await;
        tx.send(()).ok();
    });
    let started = std::time::Instant::now();
    let report = run_plant(
        plant_ep,
        async {
            rx.await.ok();
        },
        cfg,
    )
    .await
    .unwrap();
    ctl.await.unwrap();
    let wall = started.elapsed().as_secs_f64();
    assert_eq!(report.stopped_by, "shutdown");
    assert_eq!(report.frames_received, 20);
    assert_eq!(report.plant.rx_accepted.get("TCU_ClutchCmd"), Some(&20));
    // Real time: simulated time follows the wall clock (generous bounds).
    assert!(
        report.sim_time_s > 0.5 * wall - 0.05 && report.sim_time_s < wall + 0.05,
        "{} vs {wall}",
        report.sim_time_s
    );
    let lines = std::fs::read_to_string(&log).unwrap().lines().count() as u64;
    assert_eq!(
        lines,
        report.frames_sent + report.frames_received,
        "everything logged and flushed"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[tokio::test]
async fn daemon_lockstep_matches_the_in_process_profile_run() {
    // The rig controller on an in-process bus answers each ENG_Status with the profile's next
    // command; in lockstep the frames equal those of the plant running the built-in profile.
    use ddct::daemon::plant::{run as run_plant, Lockstep, Pacing, PlantDaemonConfig};
    let prof = RigProfile::from_toml_str(Path::new("short.toml"), SHORT_PROFILE).unwrap();
    let bus = InProcessBus::new("ls");
    let plant_ep = bus.endpoint(EndpointConfig::default());
    let mut ctl = bus.endpoint(EndpointConfig {
        own_echo: false,
        queue: 1 << 16,
    });
    let mut cfg = rig_config(EffectSet::nominal(), 25.0);
    cfg.sensors.torque_nm = 0.3;
    let reference = run(cfg.clone(), 3.0);
    cfg.rig_profile = None;
    cfg.rig.input_speed_rpm = prof.input_speed_rpm;
    let p2 = prof.clone();
    let controller = tokio::spawn(async move {
        let mut n = 0u64;
        let mut got = Vec::new();
        while n < 301 {
            let r = ctl.recv().await.unwrap();
            got.push(r.frame);
            if r.frame.standard_id() == Some(ids::ENG_STATUS) {
                let x = p2.x_ref((n + 1) as f64 * 0.01);
                let m = TcuClutchCmd {
                    clutch1_pos_req: x[0],
                    clutch2_pos_req: x[1],
                    ..Default::default()
                };
                ctl.send(protected(
                    ids::TCU_CLUTCH_CMD,
                    m.encode().unwrap(),
                    (n % 16) as u8,
                ))
                .await
                .unwrap();
                n += 1;
            }
        }
        got
    });
    let dcfg = PlantDaemonConfig {
        plant: cfg,
        pacing: Pacing::RealTime { speed: 50.0 },
        duration: Some(Duration::from_secs(3)),
        log: None,
        lockstep: Some(Lockstep {
            messages: vec![ids::TCU_CLUTCH_CMD],
            timeout: Duration::from_secs(5),
        }),
    };
    let report = run_plant(plant_ep, std::future::pending::<()>(), dcfg)
        .await
        .unwrap();
    let got = controller.await.unwrap();
    assert_eq!(report.lockstep_timeouts, 0);
    assert_eq!(report.pacing, "lockstep");
    let expect: Vec<CanFrame> = reference.frames.iter().map(|f| f.frame).collect();
    let n = got.len().min(expect.len());
    assert!(n >= 300 * 7);
    assert_eq!(
        &got[..n],
        &expect[..n],
        "lockstep over a bus = built-in profile in process"
    );
}

// --------------------------------------------------------------------------------------- docs

#[test]
fn docs_document_every_effect_and_fault() {
    let doc = std::fs::read_to_string("docs/plant.md").unwrap();
    for id in EffectId::ALL {
        let s = id.spec();
        assert!(
            doc.contains(&format!("**`{id}`**")),
            "{id} has no paragraph"
        );
        for p in s.params {
            // Table rows: the first cell names the effect, continuation rows leave it empty.
            let mut current = String::new();
            let row = doc
                .lines()
                .filter(|l| l.starts_with("| "))
                .find(|l| {
                    let first = l.split('|').nth(1).unwrap_or("").trim().to_string();
                    if !first.is_empty() {
                        current = first;
                    }
                    current == format!("`{id}`") && l.contains(&format!("| `{}` |", p.name))
                })
                .unwrap_or_else(|| panic!("{id}.{} has no table row", p.name));
            for needle in [
                format!("| {} |", p.unit),
                format!("{} … {}", p.plausible.0, p.plausible.1),
                format!("{} … {} |", p.bounds.0, p.bounds.1),
                format!("| {} |", p.typical),
            ] {
                assert!(
                    row.contains(&needle),
                    "{id}.{}: `{needle}` not in `{row}`",
                    p.name
                );
            }
        }
    }
    for k in FaultKind::ALL {
        assert!(
            doc.contains(&format!("| `{}` |", k.as_str())),
            "fault {} undocumented",
            k.as_str()
        );
    }
}

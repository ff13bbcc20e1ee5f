//! A minimal stand-in plant (nominal `model::powertrain` at 1 ms, exact sensors with the contract's
//! quantisation, a scripted driver) used until the plant core (`plant::Plant`, issue 5) is in
//! main. It speaks the same frames as the plant daemon.

use super::scenario::{DriverTable, Initial};
use super::PlantNode;
use crate::can::e2e::E2eSender;
use crate::can::messages::{
    ids, message_def, BenchTemps, BenchTorque, BenchVehicle, DctActuators, DctSensors, DrvPedal,
    EngStatus, GearEvenAct, GearOddAct, SimTruth, TcuClutchCmd, TcuEngineReq, TcuGearCmd,
};
use crate::can::{CanFrame, Received};
use crate::model::driveline::{self, GearShaft};
use crate::model::engine::RPM;
use crate::model::params::Params;
use crate::model::powertrain::{Inputs, Outputs, Powertrain, State};
use std::time::Duration;

fn sat(id: u16, si: usize, v: f64) -> f64 {
    let Some(def) = message_def(u32::from(id)) else {
        return 0.0;
    };
    let s = &def.signals[si];
    let v = if v.is_finite() { v } else { 0.0 };
    v.clamp(s.min, s.max)
}

/// The stand-in plant.
pub struct ModelPlant {
    pt: Powertrain,
    s: State,
    out: Outputs,
    driver: DriverTable,
    theta_h: f64,
    x_ref: [f64; 2],
    gear_req: [u8; 2],
    engine_req: Option<f64>,
    steps: u64,
    next_cycle: u64,
    tx: E2eSender,
    pending: Vec<Received>,
}

impl ModelPlant {
    pub fn new(p: Params, initial: &Initial, driver: DriverTable) -> Self {
        let pt = Powertrain::new(p);
        let mut s = State::at_rest(initial.engine_rpm, initial.temperature_c);
        s.gear_odd = GearShaft::engaged(initial.gear_odd);
        s.gear_even = GearShaft::engaged(initial.gear_even);
        s.w_out = initial.vehicle_kmh / 3.6 / p.driveline.wheel_radius_m;
        s.w_c1 =
            driveline::overall_ratio(&p.driveline, initial.gear_odd).map_or(0.0, |k| k * s.w_out);
        s.w_c2 =
            driveline::overall_ratio(&p.driveline, initial.gear_even).map_or(0.0, |k| k * s.w_out);
        let out = pt.outputs(&s, &Inputs::default());
        Self {
            pt,
            s,
            out,
            driver,
            theta_h: initial.housing_c,
            x_ref: [0.0; 2],
            gear_req: [initial.gear_odd, initial.gear_even],
            engine_req: None,
            steps: 0,
            next_cycle: 0,
            tx: E2eSender::new(),
            pending: Vec::new(),
        }
    }

    fn apply(&mut self, r: &Received) {
        let d = r.frame.bytes();
        match r.frame.standard_id() {
            Some(ids::TCU_CLUTCH_CMD) => {
                if let Ok(m) = TcuClutchCmd::decode(d) {
                    self.x_ref = [m.clutch1_pos_req, m.clutch2_pos_req];
                }
            }
            Some(ids::TCU_ENGINE_REQ) => {
                if let Ok(m) = TcuEngineReq::decode(d) {
                    self.engine_req = m.eng_torque_req_active.then_some(m.eng_torque_req);
                }
            }
            Some(ids::TCU_GEAR_CMD) => {
                if let Ok(m) = TcuGearCmd::decode(d) {
                    self.gear_req = [m.gear_odd_req as u8, m.gear_even_req as u8];
                }
            }
            _ => {}
        }
    }

    fn frames(&mut self) -> Vec<CanFrame> {
        let t = self.steps as f64 * 1e-3;
        let drv = self.driver.sample(t);
        let s = &self.s;
        let o = &self.out;
        let mut v: Vec<(u16, Result<[u8; 8], _>)> = Vec::new();
        v.push((
            ids::DRV_PEDAL,
            DrvPedal {
                accel_pedal: sat(ids::DRV_PEDAL, 0, drv.pedal * 100.0),
                brake_switch: drv.brake > 0.0,
                gear_lever: drv.lever,
                ..Default::default()
            }
            .encode(),
        ));
        v.push((
            ids::ENG_STATUS,
            EngStatus {
                eng_speed: sat(ids::ENG_STATUS, 0, s.w_f / RPM),
                eng_torque_act: sat(ids::ENG_STATUS, 1, s.engine_torque_nm),
                ..Default::default()
            }
            .encode(),
        ));
        v.push((
            ids::DCT_ACTUATORS,
            DctActuators {
                clutch1_pos: sat(ids::DCT_ACTUATORS, 0, s.x1_mm),
                clutch2_pos: sat(ids::DCT_ACTUATORS, 1, s.x2_mm),
                gear_odd_act: GearOddAct::from_raw(u64::from(s.gear_odd.engaged))
                    .unwrap_or(GearOddAct::N),
                gear_even_act: GearEvenAct::from_raw(u64::from(s.gear_even.engaged))
                    .unwrap_or(GearEvenAct::N),
                ..Default::default()
            }
            .encode(),
        ));
        v.push((
            ids::DCT_SENSORS,
            DctSensors {
                in_shaft1_speed: sat(ids::DCT_SENSORS, 0, s.w_c1 / RPM),
                in_shaft2_speed: sat(ids::DCT_SENSORS, 1, s.w_c2 / RPM),
                out_shaft_speed: sat(ids::DCT_SENSORS, 2, s.w_out / RPM),
                housing_temp: sat(ids::DCT_SENSORS, 3, self.theta_h.round()),
                ..Default::default()
            }
            .encode(),
        ));
        v.push((
            ids::BENCH_TORQUE,
            BenchTorque {
                clutch1_torque: sat(ids::BENCH_TORQUE, 0, o.t_fc1_nm),
                clutch2_torque: sat(ids::BENCH_TORQUE, 1, o.t_fc2_nm),
            }
            .encode(),
        ));
        v.push((
            ids::BENCH_TEMPS,
            BenchTemps {
                pressure_plate1_temp: sat(ids::BENCH_TEMPS, 0, s.thermal.pp1),
                pressure_plate2_temp: sat(ids::BENCH_TEMPS, 1, s.thermal.pp2),
                central_disk_temp: sat(ids::BENCH_TEMPS, 2, s.thermal.cd),
            }
            .encode(),
        ));
        v.push((
            ids::BENCH_VEHICLE,
            BenchVehicle {
                vehicle_speed: sat(ids::BENCH_VEHICLE, 0, o.vehicle_speed_mps * 3.6),
                vehicle_accel: sat(ids::BENCH_VEHICLE, 1, o.vehicle_accel_mps2),
                road_grade: sat(ids::BENCH_VEHICLE, 2, drv.grade * 100.0),
            }
            .encode(),
        ));
        v.push((
            ids::SIM_TRUTH,
            SimTruth {
                clutch1_temp_true: sat(ids::SIM_TRUTH, 0, s.thermal.c1),
                clutch2_temp_true: sat(ids::SIM_TRUTH, 1, s.thermal.c2),
            }
            .encode(),
        ));
        let mut out = Vec::new();
        for (id, d) in v {
            if let Ok(mut d) = d {
                self.tx.protect(id, &mut d);
                if let Ok(f) = CanFrame::standard(id, &d) {
                    out.push(f);
                }
            }
        }
        out
    }
}

impl PlantNode for ModelPlant {
    fn advance(&mut self, now: Duration, rx: &[Received]) -> Vec<(Duration, CanFrame)> {
        self.pending.extend_from_slice(rx);
        let target = (now.as_secs_f64() * 1e3 + 1e-6).floor() as u64;
        let mut out = Vec::new();
        loop {
            let t = Duration::from_millis(self.steps);
            let mut i = 0;
            while i < self.pending.len() {
                if self.pending[i].timestamp <= t {
                    let r = self.pending.remove(i);
                    self.apply(&r);
                } else {
                    i += 1;
                }
            }
            if self.steps == self.next_cycle * 10 {
                for f in self.frames() {
                    out.push((t, f));
                }
                self.next_cycle += 1;
            }
            if self.steps >= target {
                break;
            }
            let drv = self.driver.sample(self.steps as f64 * 1e-3);
            let u = Inputs {
                x1_ref_mm: self.x_ref[0],
                x2_ref_mm: self.x_ref[1],
                gear_odd_req: self.gear_req[0],
                gear_even_req: self.gear_req[1],
                pedal: drv.pedal,
                engine_torque_request_nm: self.engine_req,
                brake: drv.brake,
                grade: drv.grade,
                theta_h_c: self.theta_h,
            };
            let rep = self.pt.step(&mut self.s, &u, 1e-3);
            self.out = rep.outputs;
            self.steps += 1;
        }
        out
    }
}

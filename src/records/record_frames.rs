//! A bench record ([`Dataset`]) as the frames a bench would have logged: each contract message
//! that carries the record's columns, at the message's cycle time from the DBC, every value
//! saturated into its signal's range and quantised by the encoder, the E2E counter and CRC set
//! — what `ddct gap truth --mf4` writes so that generated truths reach the diagnosis through the
//! same decoding path as a logger's file. Only rig columns are encoded (a record with gear
//! columns is refused); a message some of whose columns the record lacks carries 0 there. A
//! command (TCU_ClutchCmd) is logged during the cycle before the one it acts in, as on the
//! bench, where the loader reads it so.

use crate::can::candump::LogRecord;
use crate::can::codec::CodecError;
use crate::can::e2e::E2eSender;
use crate::can::frame::CanFrame;
use crate::can::messages::{
    message_def, BenchTemps, BenchTorque, DctActuators, DctSensors, EngStatus, Message,
    TcuClutchCmd,
};
use crate::records::dataset::{Col, Dataset, RPM_TO_RADPS};
use std::time::Duration;
use thiserror::Error;

/// Why a record cannot be written as frames.
#[derive(Debug, Error)]
pub enum RecordFramesError {
    #[error("{file}: column {column} has no message here (only rig records are encoded)")]
    Unsupported { file: String, column: &'static str },
    #[error("{file}: encoding {message}: {source}")]
    Encode {
        file: String,
        message: &'static str,
        source: CodecError,
    },
}

/// The messages a rig record's columns travel in, each with the columns that decide whether it
/// is sent (at least one of them present).
const MESSAGES: &[(u16, &[Col])] = &[
    (EngStatus::ID, &[Col::Wf]),
    (DctSensors::ID, &[Col::Wc1, Col::Wc2, Col::Wout, Col::Th]),
    (DctActuators::ID, &[Col::X1, Col::X2]),
    (BenchTorque::ID, &[Col::T1, Col::T2]),
    (BenchTemps::ID, &[Col::Pp1, Col::Pp2, Col::Cd]),
    (TcuClutchCmd::ID, &[Col::X1Req, Col::X2Req]),
];

/// How long after a cycle's sensor frames the command for the next cycle is logged.
const COMMAND_AFTER_SENSORS: Duration = Duration::from_millis(2);

/// The frames of `d` on `iface`, its first sample at `start`, in time order.
pub fn frames(
    d: &Dataset,
    start: Duration,
    iface: &str,
) -> Result<Vec<LogRecord>, RecordFramesError> {
    for c in [Col::GearOdd, Col::GearEven, Col::Pedal] {
        if d.has(c) {
            return Err(RecordFramesError::Unsupported {
                file: d.source.clone(),
                column: c.name(),
            });
        }
    }
    let sent: Vec<(u16, usize)> = MESSAGES
        .iter()
        .filter(|(_, cols)| cols.iter().any(|c| d.has(*c)))
        .map(|(id, _)| {
            let cycle_s = message_def(u32::from(*id)).map_or(0.01, |m| f64::from(m.cycle_ms) / 1e3);
            (*id, ((cycle_s / d.dt).round() as usize).max(1))
        })
        .collect();
    let mut e2e = E2eSender::new();
    let mut out = Vec::new();
    let t0 = d.time.first().copied().unwrap_or(0.0);
    for i in 0..d.len() {
        let at = start + Duration::from_secs_f64((d.time[i] - t0).max(0.0));
        for (id, every) in &sent {
            if i % every != 0 {
                continue;
            }
            // A command acts from the cycle after the one it is logged in (the plant latches it,
            // and the loader reads a bus log so): the request of row i + 1 goes out during cycle
            // i, after its sensor frames.
            let (row, at) = if *id == TcuClutchCmd::ID {
                if i + 1 >= d.len() {
                    continue;
                }
                (i + 1, at + COMMAND_AFTER_SENSORS)
            } else {
                (i, at)
            };
            let msg = message(*id, d, row);
            let mut data = msg.encode().map_err(|source| RecordFramesError::Encode {
                file: d.source.clone(),
                message: message_def(u32::from(*id)).map_or("?", |m| m.name),
                source,
            })?;
            e2e.protect(*id, &mut data);
            out.push(LogRecord {
                timestamp: at,
                iface: iface.into(),
                frame: CanFrame::standard(*id, &data).expect("an 8-byte frame of a contract id"),
                direction: None,
            });
        }
    }
    out.sort_by_key(|r| r.timestamp);
    Ok(out)
}

/// Message `id` with the values of row `i` (0 for a column the record lacks), saturated.
fn message(id: u16, d: &Dataset, i: usize) -> Message {
    let v = |c: Col| d.get(c).map_or(0.0, |s| s[i]);
    let rpm = |c: Col| v(c) / RPM_TO_RADPS;
    match id {
        EngStatus::ID => Message::EngStatus(EngStatus {
            eng_speed: EngStatus::saturate_eng_speed(rpm(Col::Wf)),
            eng_torque_act: EngStatus::saturate_eng_torque_act(v(Col::Te)),
            ..Default::default()
        }),
        DctSensors::ID => Message::DctSensors(DctSensors {
            in_shaft1_speed: DctSensors::saturate_in_shaft1_speed(rpm(Col::Wc1)),
            in_shaft2_speed: DctSensors::saturate_in_shaft2_speed(rpm(Col::Wc2)),
            out_shaft_speed: DctSensors::saturate_out_shaft_speed(rpm(Col::Wout)),
            housing_temp: DctSensors::saturate_housing_temp(v(Col::Th)),
            ..Default::default()
        }),
        DctActuators::ID => Message::DctActuators(DctActuators {
            clutch1_pos: DctActuators::saturate_clutch1_pos(v(Col::X1)),
            clutch2_pos: DctActuators::saturate_clutch2_pos(v(Col::X2)),
            ..Default::default()
        }),
        BenchTorque::ID => Message::BenchTorque(BenchTorque {
            clutch1_torque: BenchTorque::saturate_clutch1_torque(v(Col::T1)),
            clutch2_torque: BenchTorque::saturate_clutch2_torque(v(Col::T2)),
        }),
        BenchTemps::ID => Message::BenchTemps(BenchTemps {
            pressure_plate1_temp: BenchTemps::saturate_pressure_plate1_temp(v(Col::Pp1)),
            pressure_plate2_temp: BenchTemps::saturate_pressure_plate2_temp(v(Col::Pp2)),
            central_disk_temp: BenchTemps::saturate_central_disk_temp(v(Col::Cd)),
        }),
        _ => Message::TcuClutchCmd(TcuClutchCmd {
            clutch1_pos_req: TcuClutchCmd::saturate_clutch1_pos_req(v(Col::X1Req)),
            clutch2_pos_req: TcuClutchCmd::saturate_clutch2_pos_req(v(Col::X2Req)),
            ..Default::default()
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::records::dataset::Segments;

    /// A record written as frames and loaded back gives its columns within one quantum.
    #[test]
    fn a_record_round_trips_through_frames_within_a_quantum() {
        let mut csv = String::from("time_s,x_to1_mm,x_to2_mm,w_f_radps,w_c1_radps,w_c2_radps,w_out_radps,T_c1_Nm,T_c2_Nm,th_pp1_C,th_pp2_C,th_cd_C,th_h_C,x_to1_req_mm,x_to2_req_mm\n");
        for i in 0..3000 {
            let t = i as f64 * 0.01;
            let s = (t * 0.7).sin();
            csv.push_str(&format!(
                "{t:.2},{:.3},{:.3},{:.4},{:.4},{:.4},0,{:.1},{:.1},{:.1},{:.1},{:.1},60,{:.3},{:.3}\n",
                4.0 + s,
                3.0 - s,
                150.0 + 10.0 * s,
                100.0 + 20.0 * s,
                80.0,
                50.0 * s,
                -20.0 * s,
                200.0 + 5.0 * s,
                190.0,
                150.0,
                4.0 + s,
                3.0 - s
            ));
        }
        let d = Dataset::from_csv("r.csv", &csv).unwrap();
        let recs = frames(&d, Duration::from_secs(1_700_000_000), "can0").unwrap();
        let text: String = recs
            .iter()
            .map(|r| crate::can::candump::format_record(r) + "\n")
            .collect();
        let back = Segments::from_candump("r.log", text.as_bytes(), d.dt).unwrap();
        let b = &back.datasets[0];
        assert_eq!(b.stats.dropped_e2e, 0);
        for (c, quantum) in [
            (Col::X1, 0.001),
            (Col::T1, 0.1),
            (Col::Pp1, 0.1),
            (Col::Wc1, 0.05),
        ] {
            let (a, z) = (d.req(c), b.req(c));
            let n = a.len().min(z.len());
            assert!(n > 2900, "{c:?}: {n}");
            let worst = (10..n - 10)
                .map(|k| (a[k] - z[k]).abs())
                .fold(0.0, f64::max);
            assert!(
                worst <= quantum * 1.01,
                "{c:?}: worst {worst}, quantum {quantum}"
            );
        }
    }
}

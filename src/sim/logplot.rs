//! `ddct log plot` (issue 13): chosen DBC signals of a recorded bus over time, optionally overlaid
//! on the lockstep simulation of the same scenario. Both runs go through the same path: their
//! frames decoded with the generated message definitions, time from the plant's first
//! DCT_Sensors frame (the bus run and the simulation start together there). Numeric signals
//! share a panel per unit (all speeds in rpm together); a signal with a value table (TcuState,
//! GearActive, GearLever, …) is a lane per label; the first frame of each new fault code in
//! TCU_Status is marked on every panel; a message silent for more than five of its cycles leaves
//! its lines open.

use super::{buslog, plots};
use crate::can::codec::{MessageDef, SignalDef};
use crate::can::messages::{ids, message_by_name, MESSAGES};
use crate::can::CanFrame;
use crate::plot::{Figure, Panel, Series, Style, PALETTE};
use std::time::Duration;
use thiserror::Error;

/// Signals drawn when none is chosen.
pub const DEFAULT_SIGNALS: &[&str] = &[
    "ENG_Status.EngSpeed",
    "DCT_Sensors.InShaft1Speed",
    "DCT_Sensors.InShaft2Speed",
    "BENCH_Torque.Clutch1Torque",
    "TCU_Estimates.Clutch1TorqueReq",
    "DCT_Actuators.Clutch1Pos",
    "TCU_ClutchCmd.Clutch1PosReq",
    "TCU_Status.TcuState",
    "TCU_Status.GearActive",
];

/// A message silent for more than this many of its cycles is a dropout (lines left open).
const GAP_CYCLES: f64 = 5.0;

#[derive(Debug, Error, PartialEq)]
pub enum LogPlotError {
    #[error("unknown signal `{0}`: give `Signal` or `Message.Signal` as in dbc/ddct.dbc (`ddct dbc show` lists them)")]
    Unknown(String),
    #[error("signal `{name}` is in several messages ({messages}): give it as `Message.{name}`")]
    Ambiguous { name: String, messages: String },
}

/// A signal of the contract.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalRef {
    pub message: &'static MessageDef,
    pub signal: &'static SignalDef,
}

impl SignalRef {
    /// `Signal` (unique in the DBC) or `Message.Signal`.
    pub fn parse(name: &str) -> Result<SignalRef, LogPlotError> {
        let unknown = || LogPlotError::Unknown(name.to_string());
        if let Some((m, s)) = name.split_once('.') {
            let message = message_by_name(m).ok_or_else(unknown)?;
            let signal = message
                .signals
                .iter()
                .find(|x| x.name == s)
                .ok_or_else(unknown)?;
            return Ok(SignalRef { message, signal });
        }
        let found: Vec<SignalRef> = MESSAGES
            .iter()
            .flat_map(|m| {
                m.signals.iter().map(move |s| SignalRef {
                    message: m,
                    signal: s,
                })
            })
            .filter(|r| r.signal.name == name)
            .collect();
        match found.as_slice() {
            [one] => Ok(*one),
            [] => Err(unknown()),
            many => Err(LogPlotError::Ambiguous {
                name: name.to_string(),
                messages: many
                    .iter()
                    .map(|r| r.message.name)
                    .collect::<Vec<_>>()
                    .join(", "),
            }),
        }
    }

    fn label(&self) -> String {
        format!("{}.{}", self.message.name, self.signal.name)
    }
}

/// The chosen signals of one run over time (s from the plant's first frame) and its fault events.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Traces {
    pub traces: Vec<(SignalRef, Vec<(f64, f64)>)>,
    pub faults: Vec<(f64, String)>,
}

/// Decodes the chosen signals from a run's frames (in time order). Frames of the wrong length are
/// skipped; values are drawn as decoded (the E2E verdict is `ddct log decode`'s business).
pub fn traces<'a>(
    frames: impl IntoIterator<Item = (Duration, &'a CanFrame)>,
    signals: &[SignalRef],
) -> Traces {
    let frames: Vec<(Duration, CanFrame)> = frames.into_iter().map(|(t, f)| (t, *f)).collect();
    let t0 = frames
        .iter()
        .find(|(_, f)| f.standard_id() == Some(ids::DCT_SENSORS))
        .or(frames.first())
        .map_or(Duration::ZERO, |(t, _)| *t);
    let secs = |t: Duration| t.as_secs_f64() - t0.as_secs_f64();
    let mut traces: Vec<(SignalRef, Vec<(f64, f64)>)> =
        signals.iter().map(|s| (*s, Vec::new())).collect();
    for (t, f) in &frames {
        let Some(id) = f.standard_id() else { continue };
        for (r, points) in traces.iter_mut() {
            if r.message.id == id {
                if let Ok(p) = r.message.payload(f.bytes()) {
                    points.push((secs(*t), r.signal.decode_physical(p)));
                }
            }
        }
    }
    // The fault events as the run figures mark them (their times count from the first frame).
    let shift = frames.first().map_or(0.0, |(t, _)| secs(*t));
    let faults = plots::fault_events(&buslog::rows(&frames))
        .into_iter()
        .map(|(t, label)| (t + shift, label))
        .collect();
    Traces { traces, faults }
}

fn series(name: String, r: &SignalRef, points: &[(f64, f64)]) -> Series {
    let gap = GAP_CYCLES * f64::from(r.message.cycle_ms.max(10)) * 1e-3;
    let s = Series::line(name, points.to_vec()).max_gap(gap);
    if r.signal.values.is_empty() {
        s
    } else {
        s.steps()
    }
}

/// The figure as an SVG document: the bus run solid, the simulation (if any) dashed in the
/// same colour.
pub fn figure(title: &str, bus: &Traces, sim: Option<&Traces>) -> String {
    let mut panels: Vec<(String, Panel)> = Vec::new();
    for (k, (r, points)) in bus.traces.iter().enumerate() {
        let color = PALETTE[k % PALETTE.len()];
        let lane = !r.signal.values.is_empty();
        let key = if lane {
            r.label()
        } else {
            format!("unit:{}", r.signal.unit)
        };
        let at = match panels.iter().position(|(k, _)| *k == key) {
            Some(i) => i,
            None => {
                let panel = if lane {
                    let top = r.signal.values.iter().map(|v| v.0).max().unwrap_or(0) as f64;
                    let mut p = Panel::new(r.label(), "t (s)", "")
                        .y_range(-0.5, top + 0.5)
                        .y_labels(
                            r.signal
                                .values
                                .iter()
                                .map(|(v, l)| (*v as f64, l.to_string()))
                                .collect(),
                        );
                    p.legend = sim.is_some();
                    p
                } else {
                    let unit = if r.signal.unit.is_empty() {
                        "-"
                    } else {
                        r.signal.unit
                    };
                    Panel::new(format!("Signals in {unit}"), "t (s)", format!("({unit})"))
                };
                panels.push((key, panel));
                panels.len() - 1
            }
        };
        let p = &mut panels[at].1;
        let suffix = if sim.is_some() { " (bus)" } else { "" };
        p.add(series(format!("{}{suffix}", r.label()), r, points).color(color));
        if let Some(pts) = sim
            .and_then(|s| s.traces.iter().find(|(x, _)| x == r))
            .map(|x| &x.1)
        {
            p.add(
                series(format!("{} (sim)", r.label()), r, pts)
                    .color(color)
                    .style(Style::Dashed),
            );
        }
    }
    let mut fig = Figure::new(title, 1);
    for (_, mut p) in panels {
        for (t, label) in &bus.faults {
            p.marker(*t, label.clone());
        }
        fig = fig.panel(p);
    }
    fig.to_svg()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::messages::{EngStatus, FaultCode, TcuStatus};

    #[test]
    fn signals_by_name_or_message_and_name() {
        let r = SignalRef::parse("EngSpeed").unwrap();
        assert_eq!((r.message.name, r.signal.unit), ("ENG_Status", "rpm"));
        assert_eq!(
            SignalRef::parse("TCU_Status.TcuState").unwrap().signal.name,
            "TcuState"
        );
        assert!(matches!(
            SignalRef::parse("Crc"),
            Err(LogPlotError::Ambiguous { .. })
        ));
        assert_eq!(
            SignalRef::parse("ENG_Status.Nope"),
            Err(LogPlotError::Unknown("ENG_Status.Nope".into()))
        );
        for s in DEFAULT_SIGNALS {
            SignalRef::parse(s).unwrap();
        }
    }

    /// Values decoded back as encoded, time from the first DCT_Sensors frame, a new fault code
    /// marked once.
    #[test]
    fn traces_decode_the_chosen_signals_and_mark_new_fault_codes() {
        let eng = |rpm: f64| {
            let m = EngStatus {
                eng_speed: rpm,
                ..Default::default()
            };
            CanFrame::standard(EngStatus::ID, &m.encode().unwrap()).unwrap()
        };
        let status = |fault: FaultCode| {
            let m = TcuStatus {
                fault_code: fault,
                ..Default::default()
            };
            CanFrame::standard(TcuStatus::ID, &m.encode().unwrap()).unwrap()
        };
        let sensors = CanFrame::standard(ids::DCT_SENSORS, &[0; 8]).unwrap();
        let ms = Duration::from_millis;
        let frames = [
            (ms(1000), eng(800.0)),
            (ms(1010), sensors),
            (ms(1020), eng(1500.5)),
            (ms(1030), status(FaultCode::None)),
            (ms(1040), status(FaultCode::PedalTimeout)),
            (ms(1050), status(FaultCode::PedalTimeout)),
            (ms(1060), eng(900.0)),
        ];
        let r = SignalRef::parse("EngSpeed").unwrap();
        let t = traces(frames.iter().map(|(t, f)| (*t, f)), &[r]);
        let pts = &t.traces[0].1;
        assert_eq!(pts.len(), 3);
        assert!((pts[0].0 + 0.01).abs() < 1e-9 && (pts[0].1 - 800.0).abs() < 1e-9);
        assert!((pts[1].0 - 0.01).abs() < 1e-9 && (pts[1].1 - 1500.5).abs() < 1e-9);
        assert_eq!(t.faults.len(), 1);
        assert!((t.faults[0].0 - 0.03).abs() < 1e-9);
        assert_eq!(t.faults[0].1, "PedalTimeout");
        let svg = figure("t", &t, Some(&t));
        assert!(
            svg.contains("ENG_Status.EngSpeed (bus)") && svg.contains("ENG_Status.EngSpeed (sim)")
        );
        assert!(svg.contains("PedalTimeout"));
    }
}

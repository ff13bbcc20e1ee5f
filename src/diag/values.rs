//! The TCU's internals and calibrations reachable on the bus: one table from which the UDS data
//! identifiers ([`super::uds`]), the XCP slave's memory map ([`super::xcp`]) and the A2L file
//! ([`super::a2l`]) are all derived, so a name, unit, address or limit is written once.
//!
//! - A [`Measurement`] is read from a [`Snapshot`] of one TCU step (the values of (17) and
//!   (23)–(27): estimated clutch temperatures, torque and position references, kiss points
//!   x_ISP(θ̂) of (9), state and gear).
//! - A [`Calibration`] is a key of the TCU calibration ([`crate::tcu::TcuConfig`]), which the
//!   TCU core owns ([`crate::tcu::calibration`]); here it gets its unit and declared range;
//!   a write is range-checked by the calibration's own validation and takes effect at the next
//!   cycle ([`crate::tcu::Tcu::set_calibration`]).
//!
//! XCP addresses: measurement `i` is the `f32` at [`MEASUREMENT_BASE`] + 4·i, calibration `i` the
//! `f32` at [`CALIBRATION_BASE`] + 4·i (little-endian, the byte order of the A2L's
//! `BYTE_ORDER MSB_LAST`).

use crate::can::messages::{FaultCode, TcuState};
use crate::model::gear::Gear;
pub use crate::tcu::calibration::Calibration;
use crate::tcu::TcuOutputs;

/// Address of the first measurement in the XCP memory map.
pub const MEASUREMENT_BASE: u32 = 0x0001_0000;
/// Address of the first calibration in the XCP memory map.
pub const CALIBRATION_BASE: u32 = 0x0002_0000;

const RADPS_TO_RPM: f64 = 60.0 / std::f64::consts::TAU;

/// The values of one TCU step that measurements read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Snapshot {
    /// TCU time (s).
    pub t_s: f64,
    pub state: TcuState,
    pub fault: FaultCode,
    /// The gear transmitting torque (TCU_Status GearActive).
    pub gear_active: Gear,
    /// Estimated clutch temperatures θ̂_c1, θ̂_c2 (°C), (17).
    pub theta_est_c: [f64; 2],
    /// Clutch torque references (N·m), (23)–(27).
    pub t_ref_nm: [f64; 2],
    /// Bearing position requests (mm).
    pub x_ref_mm: [f64; 2],
    /// Measured bearing positions (mm).
    pub x_mm: [f64; 2],
    /// Kiss points x_ISP(θ̂) of the TCU's clutch model (mm), (9).
    pub kiss_mm: [f64; 2],
    /// Engine speed (rpm).
    pub engine_rpm: f64,
    /// Input-shaft speeds (rpm).
    pub shaft_rpm: [f64; 2],
    /// Output-shaft speed (rpm).
    pub out_rpm: f64,
    /// Accelerator pedal (%).
    pub pedal_pct: f64,
    /// Housing air temperature (°C).
    pub housing_c: f64,
}

impl Snapshot {
    /// The snapshot of one step's outputs, with the model's kiss points at the estimated
    /// temperatures.
    pub fn new(o: &TcuOutputs, kiss_mm: [f64; 2]) -> Snapshot {
        let t = &o.trace;
        let m = &t.measurements;
        Snapshot {
            t_s: t.t_s,
            state: t.state,
            fault: t.fault,
            gear_active: Gear::from(o.status.gear_active),
            theta_est_c: t.theta_est_c,
            t_ref_nm: t.t_ref_nm,
            x_ref_mm: t.x_ref_mm,
            x_mm: m.x_mm,
            kiss_mm,
            engine_rpm: m.w_e * RADPS_TO_RPM,
            shaft_rpm: m.w_c.map(|w| w * RADPS_TO_RPM),
            out_rpm: m.w_out * RADPS_TO_RPM,
            pedal_pct: m.pedal * 100.0,
            housing_c: m.theta_h,
        }
    }
}

/// One measurable value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Measurement {
    Clutch1TempEst,
    Clutch2TempEst,
    Clutch1TorqueRef,
    Clutch2TorqueRef,
    Clutch1PosRef,
    Clutch2PosRef,
    Clutch1Pos,
    Clutch2Pos,
    Clutch1KissPoint,
    Clutch2KissPoint,
    EngineSpeed,
    InShaft1Speed,
    InShaft2Speed,
    OutShaftSpeed,
    AccelPedal,
    HousingTemp,
    TcuState,
    GearActive,
    FaultCode,
}

/// What a table row says about a value: its A2L name, unit, description and physical limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Meta {
    pub name: &'static str,
    pub unit: &'static str,
    pub doc: &'static str,
    pub min: f64,
    pub max: f64,
}

const fn meta(
    name: &'static str,
    unit: &'static str,
    doc: &'static str,
    min: f64,
    max: f64,
) -> Meta {
    Meta {
        name,
        unit,
        doc,
        min,
        max,
    }
}

/// The measurements' names, units, descriptions and limits, in the order of
/// [`Measurement::ALL`] (the unit test `meta_follows_all` holds the names to the variants).
#[rustfmt::skip]
const MEASUREMENT_META: [Meta; 19] = [
    meta("Clutch1TempEst", "degC", "Estimated clutch 1 temperature (17)", -40.0, 400.0),
    meta("Clutch2TempEst", "degC", "Estimated clutch 2 temperature (17)", -40.0, 400.0),
    meta("Clutch1TorqueRef", "Nm", "Clutch 1 torque reference (23)-(27)", -1000.0, 1000.0),
    meta("Clutch2TorqueRef", "Nm", "Clutch 2 torque reference (23)-(27)", -1000.0, 1000.0),
    meta("Clutch1PosRef", "mm", "Clutch 1 bearing position request", 0.0, 16.0),
    meta("Clutch2PosRef", "mm", "Clutch 2 bearing position request", 0.0, 16.0),
    meta("Clutch1Pos", "mm", "Clutch 1 measured bearing position", 0.0, 16.0),
    meta("Clutch2Pos", "mm", "Clutch 2 measured bearing position", 0.0, 16.0),
    meta("Clutch1KissPoint", "mm", "Clutch 1 kiss point x_ISP at the estimated temperature (9)", 0.0, 16.0),
    meta("Clutch2KissPoint", "mm", "Clutch 2 kiss point x_ISP at the estimated temperature (9)", 0.0, 16.0),
    meta("EngineSpeed", "rpm", "Engine speed (measured)", 0.0, 10000.0),
    meta("InShaft1Speed", "rpm", "Odd input shaft speed (measured)", -8192.0, 8192.0),
    meta("InShaft2Speed", "rpm", "Even input shaft speed (measured)", -8192.0, 8192.0),
    meta("OutShaftSpeed", "rpm", "Output shaft speed (measured)", -4096.0, 4096.0),
    meta("AccelPedal", "%", "Accelerator pedal", 0.0, 100.0),
    meta("HousingTemp", "degC", "Clutch housing air temperature (measured)", -40.0, 215.0),
    meta("TcuState", "", "TCU state (TCU_Status TcuState)", 0.0, 8.0),
    meta("GearActive", "", "Gear transmitting torque (7 = reverse)", 0.0, 7.0),
    meta("FaultCode", "", "Active fault code (TCU_Status FaultCode)", 0.0, 255.0),
];

impl Measurement {
    /// Every measurement, in address order.
    pub const ALL: [Measurement; 19] = [
        Measurement::Clutch1TempEst,
        Measurement::Clutch2TempEst,
        Measurement::Clutch1TorqueRef,
        Measurement::Clutch2TorqueRef,
        Measurement::Clutch1PosRef,
        Measurement::Clutch2PosRef,
        Measurement::Clutch1Pos,
        Measurement::Clutch2Pos,
        Measurement::Clutch1KissPoint,
        Measurement::Clutch2KissPoint,
        Measurement::EngineSpeed,
        Measurement::InShaft1Speed,
        Measurement::InShaft2Speed,
        Measurement::OutShaftSpeed,
        Measurement::AccelPedal,
        Measurement::HousingTemp,
        Measurement::TcuState,
        Measurement::GearActive,
        Measurement::FaultCode,
    ];

    /// Name, unit, description and limits.
    pub fn meta(self) -> Meta {
        MEASUREMENT_META[self.index()]
    }

    /// The value in `s` (the unit of [`Measurement::meta`]).
    pub fn value(self, s: &Snapshot) -> f64 {
        use Measurement::*;
        match self {
            Clutch1TempEst => s.theta_est_c[0],
            Clutch2TempEst => s.theta_est_c[1],
            Clutch1TorqueRef => s.t_ref_nm[0],
            Clutch2TorqueRef => s.t_ref_nm[1],
            Clutch1PosRef => s.x_ref_mm[0],
            Clutch2PosRef => s.x_ref_mm[1],
            Clutch1Pos => s.x_mm[0],
            Clutch2Pos => s.x_mm[1],
            Clutch1KissPoint => s.kiss_mm[0],
            Clutch2KissPoint => s.kiss_mm[1],
            EngineSpeed => s.engine_rpm,
            InShaft1Speed => s.shaft_rpm[0],
            InShaft2Speed => s.shaft_rpm[1],
            OutShaftSpeed => s.out_rpm,
            AccelPedal => s.pedal_pct,
            HousingTemp => s.housing_c,
            TcuState => f64::from(s.state as u8),
            GearActive => f64::from(s.gear_active.code()),
            FaultCode => f64::from(s.fault as u8),
        }
    }

    /// Its XCP address.
    pub fn address(self) -> u32 {
        MEASUREMENT_BASE + 4 * Self::index(self) as u32
    }

    fn index(self) -> usize {
        Self::ALL.iter().position(|m| *m == self).unwrap_or(0)
    }

    /// The measurement at an XCP address (the start of its `f32`).
    pub fn at(address: u32) -> Option<Measurement> {
        let off = address.checked_sub(MEASUREMENT_BASE)?;
        (off % 4 == 0)
            .then(|| Self::ALL.get((off / 4) as usize).copied())
            .flatten()
    }
}

/// What the bus says of a TCU calibration: its A2L name (the calibration key), unit, limits
/// and XCP address.
impl Calibration {
    /// Name, unit, description and limits (the key's declared range in the calibration; the
    /// unit test `limits_are_the_calibration_ranges` holds them to it).
    pub fn meta(self) -> Meta {
        use Calibration::*;
        match self {
            ClutchKp => meta(
                self.key(),
                "1/s",
                "Clutch speed controller proportional gain",
                0.0,
                200.0,
            ),
            ClutchKi => meta(
                self.key(),
                "1/s^2",
                "Clutch speed controller integral gain",
                0.0,
                5000.0,
            ),
            EngineKp => meta(
                self.key(),
                "1/s",
                "Engine speed controller proportional gain",
                0.0,
                200.0,
            ),
            EngineKi => meta(
                self.key(),
                "1/s^2",
                "Engine speed controller integral gain",
                0.0,
                5000.0,
            ),
            LaunchLockupTime => meta(self.key(), "s", "Launch lock-up time", 0.2, 10.0),
            OverTempWarn => meta(
                self.key(),
                "degC",
                "Over-temperature warning threshold",
                50.0,
                400.0,
            ),
            CompTemperature => meta(
                self.key(),
                "",
                "Temperature compensation of the inverse (0 off, 1 on)",
                0.0,
                1.0,
            ),
            CompSlip => meta(
                self.key(),
                "",
                "Slip compensation of the inverse (0 off, 1 on)",
                0.0,
                1.0,
            ),
        }
    }

    /// The A2L-friendly name (dots replaced).
    pub fn symbol(self) -> String {
        self.meta().name.replace('.', "_")
    }

    /// Its XCP address.
    pub fn address(self) -> u32 {
        CALIBRATION_BASE + 4 * Self::ALL.iter().position(|m| *m == self).unwrap_or(0) as u32
    }

    /// The calibration at an XCP address (the start of its `f32`).
    pub fn at(address: u32) -> Option<Calibration> {
        let off = address.checked_sub(CALIBRATION_BASE)?;
        (off % 4 == 0)
            .then(|| Self::ALL.get((off / 4) as usize).copied())
            .flatten()
    }
}

/// A TCU in Drive, 2nd gear, at `t_s`: the snapshot of the diagnostic cores' unit tests.
#[cfg(test)]
pub(crate) fn test_snapshot(t_s: f64) -> Snapshot {
    Snapshot {
        t_s,
        state: TcuState::Drive,
        fault: FaultCode::None,
        gear_active: Gear::G2,
        theta_est_c: [120.0, 95.5],
        t_ref_nm: [10.0, 0.0],
        x_ref_mm: [5.0, 1.0],
        x_mm: [5.25, 1.5],
        kiss_mm: [4.0, 4.1],
        engine_rpm: 2000.0,
        shaft_rpm: [1500.0, 900.0],
        out_rpm: 450.0,
        pedal_pct: 30.0,
        housing_c: 60.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tcu::TcuConfig;

    #[test]
    fn limits_are_the_calibration_ranges() {
        for cal in Calibration::ALL.into_iter().filter(|c| !c.is_switch()) {
            let m = cal.meta();
            let base = TcuConfig::default();
            for (v, ok) in [
                (m.min, true),
                (m.max, true),
                (m.min - 1e-6 * m.min.abs().max(1.0), false),
                (m.max + 1e-6 * m.max.abs().max(1.0), false),
            ] {
                let mut c = base.clone();
                cal.put(&mut c, v);
                // over_temp_limit_c must stay above the warning: raise it with the warning.
                if cal == Calibration::OverTempWarn && v <= 400.0 {
                    c.safety.over_temp_limit_c = c.safety.over_temp_limit_c.max(v);
                }
                assert_eq!(c.validate().is_ok(), ok, "{} = {v}", m.name);
            }
        }
    }

    #[test]
    fn meta_follows_all() {
        for m in Measurement::ALL {
            assert_eq!(m.meta().name, format!("{m:?}"));
        }
    }

    #[test]
    fn addresses_round_trip() {
        for m in Measurement::ALL {
            assert_eq!(Measurement::at(m.address()), Some(m));
            assert_eq!(Measurement::at(m.address() + 1), None);
        }
        for c in Calibration::ALL {
            assert_eq!(Calibration::at(c.address()), Some(c));
            assert!(Calibration::get(c, &TcuConfig::default()).is_finite());
        }
        assert_eq!(Measurement::at(MEASUREMENT_BASE + 4 * 19), None);
    }
}

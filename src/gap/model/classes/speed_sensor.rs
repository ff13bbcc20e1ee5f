//! The speed sensors' class (issue 43): the input-shaft (or dyno), clutch and engine speed
//! channels read with a gain error and late or early, measured ω(t) = gain·ω(t − skew). The
//! transmission is as modelled, but the slip the model is given is not the slip the clutch
//! had: the slip dependence Q(ω) of (6) is taken at the wrong slip, and the friction power
//! T·ω_fc that heats the plates and disks in (16c)–(16e) is wrong by the gain. Its fit corrects
//! the record's speeds ([`crate::gap::model::terms::SpeedSensor`]), recomputes the friction
//! power and energy and replays the temperatures: fitted on the thermocouples, where a gain
//! shows, and on the torque, which the corrected disk temperature and Q(ω) move.

use super::basis::Basis;
use super::common::no_temperatures;
use super::effect_class::EffectClass;
use super::knots::{Has, Knots, Needs};
use crate::gap::fit::lsq::ParamSpec;
use crate::gap::model::candidate::Model;
use crate::gap::model::class::ClassId;
use crate::gap::model::terms::SpeedSensor;
use crate::model::effects::Subsystem;

/// The speed channels' gain and time skew.
pub struct Speed;

impl EffectClass for Speed {
    fn id(&self) -> ClassId {
        ClassId::SensorSpeed
    }
    fn group(&self) -> Subsystem {
        Subsystem::Thermal
    }
    fn also_fitted_on(&self) -> &'static [Subsystem] {
        &[Subsystem::TorqueCharacteristic]
    }
    /// The corrected friction energy moves the torque's energy terms (the kiss point's wear of
    /// (9)): the torque characteristic is recalibrated with it, as with a thermocouple's error.
    fn recalibrates_also(&self) -> &'static [Subsystem] {
        &[Subsystem::TorqueCharacteristic]
    }
    fn not_checkable(&self, _knots: &Knots, has: Has) -> Option<String> {
        (!has(Needs::Temperatures)).then(no_temperatures)
    }
    /// The corrected speeds move the friction power, so the disk estimate cached from the
    /// speeds as read does not hold.
    fn reads_cached_disk(&self) -> bool {
        false
    }
    /// Every evaluation corrects the record's speeds and replays the temperatures.
    fn fit_cost(&self) -> u8 {
        2
    }
    fn params(&self, _base: &Model) -> Vec<ParamSpec> {
        vec![
            ParamSpec::new("sensor_speed.gain", 1.0, 0.8, 1.25, 0.01),
            ParamSpec::new("sensor_speed.skew_s", 0.0, -0.2, 0.2, 0.01),
        ]
    }
    fn apply(&self, _knots: &Knots, m: &mut Model, v: &[f64]) {
        m.terms.speed_sensor = Some(SpeedSensor {
            gain: v[0],
            skew_s: v.get(1).copied().unwrap_or(0.0),
        });
    }
    fn clear(&self, m: &mut Model, _reference: &Model) {
        m.terms.speed_sensor = None;
    }
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        (
            m.terms.speed_sensor.map_or(0.0, |s| s.gain - 1.0),
            "1, relative gain error of the speed channels",
        )
    }
    fn basis(&self, _m: &Model) -> Basis {
        Basis::Parameter
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::model::classes::knots::Knots;

    #[test]
    fn the_parameters_set_and_clear_the_speed_term_and_the_magnitude_is_the_gain_error() {
        let nominal = Model::nominal(crate::model::params::Params::default());
        let mut m = nominal;
        Speed.apply(&Knots::default(), &mut m, &[1.03, 0.05]);
        assert_eq!(
            m.terms.speed_sensor,
            Some(SpeedSensor {
                gain: 1.03,
                skew_s: 0.05
            })
        );
        assert!(m.terms.touches_torque());
        let (mag, unit) = Speed.magnitude(&m);
        assert!((mag - 0.03).abs() < 1e-12, "{mag}");
        assert!(unit.starts_with('1'));
        Speed.clear(&mut m, &nominal);
        assert!(m.terms.is_nominal());
    }

    #[test]
    fn true_speeds_undo_the_gain_and_read_the_skew_ahead() {
        // A ramp ω = 10·t sampled every 10 ms, read 3 % high and 20 ms late: the true speed at
        // sample k is the measured one two samples on, over 1.03; held at the end.
        let dt = 0.01;
        let truth: Vec<f64> = (0..50).map(|k| 10.0 * k as f64 * dt).collect();
        let measured: Vec<f64> = (0..50).map(|k| 1.03 * truth[k.max(2) - 2]).collect();
        let s = SpeedSensor {
            gain: 1.03,
            skew_s: 0.02,
        };
        let back: Vec<f64> = s.true_speeds(&measured, dt);
        for k in 2..48 {
            assert!((back[k] - truth[k]).abs() < 1e-12, "sample {k}");
        }
        assert!((back[49] - truth[47]).abs() < 1e-12);
        // A skew between samples interpolates.
        let half = SpeedSensor {
            gain: 1.0,
            skew_s: 0.005,
        };
        assert!((half.true_speeds::<Vec<f64>>(&truth, dt)[10] - 10.0 * 0.105).abs() < 1e-12);
    }
}

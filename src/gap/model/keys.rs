//! The model parameters the identification (the paper's procedure, §4) and the recalibration
//! re-fit, typed ([`ParamKey`]): each with its `table.key` name in `config/params.toml` (e.g.
//! `clutch.x_isp1_mm_per_c`), its unit, its solver scale, its allowed range from the parameter
//! file's specification and the subsystem whose equation it enters ((9) kiss point, (4)–(6)
//! friction, (16) thermal, the actuator's lag). A name that is not a key is an error where it is
//! parsed, never a zero.

use crate::model::effects::Subsystem;
use crate::model::params::{ActuatorParams, ClutchParams, Params, Spec, ThermalParams5};
use std::fmt;

macro_rules! param_keys {
    ($( $id:ident = $table:ident . $field:ident, $unit:literal, $scale:expr, $sub:ident; )*) => {
        /// A fittable model parameter.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum ParamKey { $( $id, )* }

        impl ParamKey {
            /// Every key, in declaration order.
            pub const ALL: &'static [ParamKey] = &[ $( ParamKey::$id, )* ];

            /// The `table.key` name of `config/params.toml`.
            pub fn as_str(self) -> &'static str {
                match self { $( ParamKey::$id => concat!(stringify!($table), ".", stringify!($field)), )* }
            }

            /// Its unit.
            pub fn unit(self) -> &'static str {
                match self { $( ParamKey::$id => $unit, )* }
            }

            /// Typical magnitude: the solver scale.
            pub fn scale(self) -> f64 {
                match self { $( ParamKey::$id => $scale, )* }
            }

            /// The subsystem whose equation it enters.
            pub fn subsystem(self) -> Subsystem {
                match self { $( ParamKey::$id => Subsystem::$sub, )* }
            }

            /// Its value in `p`.
            pub fn get(self, p: &Params) -> f64 {
                match self { $( ParamKey::$id => p.$table.$field, )* }
            }

            /// Sets its value in `p`.
            pub fn set(self, p: &mut Params, value: f64) {
                match self { $( ParamKey::$id => p.$table.$field = value, )* }
            }

            fn table_specs(self) -> (&'static [Spec], &'static str) {
                match self { $( ParamKey::$id => (specs(stringify!($table)), stringify!($field)), )* }
            }
        }
    };
}

param_keys! {
    XIsp0 = clutch.x_isp0_mm, "mm", 1.0, TorqueCharacteristic;
    XIsp1 = clutch.x_isp1_mm_per_c, "mm/°C", 1e-3, TorqueCharacteristic;
    XIsp2 = clutch.x_isp2_mm_per_c2, "mm/°C²", 1e-6, TorqueCharacteristic;
    XToMax = clutch.x_to_max_mm, "mm", 1.0, TorqueCharacteristic;
    C4 = clutch.c4, "-", 0.01, TorqueCharacteristic;
    MuS = clutch.mu_s, "-", 0.01, TorqueCharacteristic;
    Alpha1 = thermal5.alpha1_per_s, "1/s", 1e-3, Thermal;
    Alpha2 = thermal5.alpha2_per_s, "1/s", 1e-3, Thermal;
    Alpha3 = thermal5.alpha3_k_per_j, "K/J", 1e-4, Thermal;
    Alpha4 = thermal5.alpha4_per_s, "1/s", 1e-3, Thermal;
    Alpha5 = thermal5.alpha5_per_s, "1/s", 1e-3, Thermal;
    Alpha6 = thermal5.alpha6_per_s, "1/s", 1e-3, Thermal;
    Alpha7 = thermal5.alpha7_k_per_j, "K/J", 1e-4, Thermal;
    Alpha8 = thermal5.alpha8_per_s, "1/s", 1e-3, Thermal;
    Alpha9 = thermal5.alpha9_k_per_j, "K/J", 1e-4, Thermal;
    TauS = actuator.tau_s, "s", 1e-2, Actuator;
}

fn specs(table: &str) -> &'static [Spec] {
    match table {
        "clutch" => ClutchParams::SPECS,
        "thermal5" => ThermalParams5::SPECS,
        _ => ActuatorParams::SPECS,
    }
}

impl ParamKey {
    /// Parses a `table.key` name.
    pub fn parse(s: &str) -> Option<ParamKey> {
        ParamKey::ALL.iter().copied().find(|k| k.as_str() == s)
    }

    /// Allowed range from the parameter file's specification.
    pub fn range(self) -> (f64, f64) {
        let (specs, name) = self.table_specs();
        specs
            .iter()
            .find(|s| s.key == name)
            .map_or((f64::NEG_INFINITY, f64::INFINITY), |s| (s.min, s.max))
    }

    /// True for the thermal model's rates and gains.
    pub fn is_thermal(self) -> bool {
        self.subsystem() == Subsystem::Thermal
    }
}

impl fmt::Display for ParamKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.as_str())
    }
}

impl serde::Serialize for ParamKey {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_key_round_trips_and_has_its_files_range() {
        let mut p = Params::default();
        for &k in ParamKey::ALL {
            assert_eq!(ParamKey::parse(k.as_str()), Some(k));
            let v = k.get(&p);
            k.set(&mut p, v * 2.0 + 1e-9);
            assert_eq!(k.get(&p), v * 2.0 + 1e-9);
            let (lo, hi) = k.range();
            assert!(lo.is_finite() && hi.is_finite() && lo < hi, "{k}");
        }
        assert!(ParamKey::parse("clutch.nope").is_none());
        assert_eq!(ParamKey::XIsp1.get(&Params::default()), -2.5e-3);
        assert_eq!(ParamKey::XIsp1.as_str(), "clutch.x_isp1_mm_per_c");
    }
}

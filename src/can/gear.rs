//! The boundary between the model's [`Gear`] and the gear codes of the DBC's value tables
//! (`GearOddReq`/`GearEvenReq` of TCU_GearCmd, `GearOddAct`/`GearEvenAct` of DCT_Actuators,
//! `GearActive` of TCU_Status). Every table's labels are gear names (`N`, `G1`…`G6`, `R`), and so
//! are the generated variants, so a value converts variant by variant (a `match`, no string
//! comparison on the frame path): a shaft's table into a gear always, a gear into a shaft's table
//! only when the gear is on that shaft (or neutral), and a bare code (a CSV column, a config
//! value) only when it is in the `GearActive` table — never Neutral by accident.

use super::messages::{GearActive, GearEvenAct, GearEvenReq, GearOddAct, GearOddReq};
use crate::model::gear::Gear;
use thiserror::Error;

/// Why a gear cannot be written in a value table.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GearError {
    #[error("gear {gear} is not on the {table} shaft")]
    WrongShaft { gear: Gear, table: &'static str },
    #[error("gear code {code} is not in the DBC's gear table (0 N, 1–6, 7 R)")]
    UnknownCode { code: f64 },
}

/// Conversions by variant, checked by the compiler: the generated tables' variants are named
/// by their labels, the same names as [`Gear`]'s (`N`, `G1`…`G6`, `R`), so a table that lost or
/// renamed a gear fails to build instead of mapping it to neutral.
macro_rules! table {
    ($t:ident, $name:literal, [$($v:ident),+]) => {
        impl From<$t> for Gear {
            fn from(v: $t) -> Gear {
                match v {
                    $($t::$v => Gear::$v,)+
                }
            }
        }
        impl TryFrom<Gear> for $t {
            type Error = GearError;
            fn try_from(g: Gear) -> Result<$t, GearError> {
                match g {
                    $(Gear::$v => Ok($t::$v),)+
                    _ => Err(GearError::WrongShaft {
                        gear: g,
                        table: $name,
                    }),
                }
            }
        }
    };
}

table!(GearOddReq, "odd", [N, G1, G3, G5]);
table!(GearEvenReq, "even", [N, G2, G4, G6, R]);
table!(GearOddAct, "odd", [N, G1, G3, G5]);
table!(GearEvenAct, "even", [N, G2, G4, G6, R]);

impl From<GearActive> for Gear {
    fn from(v: GearActive) -> Gear {
        use GearActive as A;
        match v {
            A::N => Gear::N,
            A::G1 => Gear::G1,
            A::G2 => Gear::G2,
            A::G3 => Gear::G3,
            A::G4 => Gear::G4,
            A::G5 => Gear::G5,
            A::G6 => Gear::G6,
            A::R => Gear::R,
        }
    }
}

/// Every gear is in `GearActive`'s table.
impl From<Gear> for GearActive {
    fn from(g: Gear) -> GearActive {
        use GearActive as A;
        match g {
            Gear::N => A::N,
            Gear::G1 => A::G1,
            Gear::G2 => A::G2,
            Gear::G3 => A::G3,
            Gear::G4 => A::G4,
            Gear::G5 => A::G5,
            Gear::G6 => A::G6,
            Gear::R => A::R,
        }
    }
}

impl Gear {
    /// The gear of a bus code (`GearActive`'s table: 0 N, 1–6, 7 R), e.g. a CSV gear column;
    /// anything else, a fraction included, is an error.
    pub fn from_code(code: f64) -> Result<Gear, GearError> {
        let raw = (code.fract() == 0.0 && (0.0..=255.0).contains(&code)).then_some(code as u64);
        raw.and_then(GearActive::from_raw)
            .map(Gear::from)
            .ok_or(GearError::UnknownCode { code })
    }

    /// The bus code of the gear (`GearActive`'s table).
    pub fn code(self) -> u8 {
        GearActive::from(self) as u8
    }
}

/// A gear is written as its bus code (configs, reports, state files).
impl serde::Serialize for Gear {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u8(self.code())
    }
}

/// A gear is read from its bus code (0 N, 1–6, 7 R) or its label (`"N"`, `"G3"`, `"R"`); an
/// unknown code or label is an error (a config's error then names the file, line and key).
impl<'de> serde::Deserialize<'de> for Gear {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Gear, D::Error> {
        #[derive(serde::Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Code(f64),
            Label(String),
        }
        match Raw::deserialize(d)? {
            Raw::Code(c) => Gear::from_code(c).map_err(serde::de::Error::custom),
            Raw::Label(l) => GearActive::ALL
                .iter()
                .find(|g| g.label() == l)
                .map(|g| Gear::from(*g))
                .ok_or_else(|| {
                    serde::de::Error::custom(format!(
                        "gear `{l}` is not in the DBC's gear table (N, G1…G6, R)"
                    ))
                }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the DBC's value tables as written (dbc/ddct.dbc, VAL_ 290, 291, 305).
    #[test]
    fn every_table_value_round_trips_and_wrong_shafts_are_errors() {
        let codes = [
            (0.0, Gear::N),
            (1.0, Gear::G1),
            (2.0, Gear::G2),
            (3.0, Gear::G3),
            (4.0, Gear::G4),
            (5.0, Gear::G5),
            (6.0, Gear::G6),
            (7.0, Gear::R),
        ];
        for (c, g) in codes {
            assert_eq!(Gear::from_code(c), Ok(g));
            assert_eq!(f64::from(g.code()), c);
            assert_eq!(Gear::from(GearActive::from(g)), g);
        }
        for bad in [8.0, -1.0, 1.5, f64::NAN, 300.0] {
            assert!(Gear::from_code(bad).is_err(), "{bad}");
        }
        for &v in GearOddReq::ALL.iter() {
            assert_eq!(GearOddReq::try_from(Gear::from(v)), Ok(v));
        }
        for &v in GearEvenAct::ALL.iter() {
            assert_eq!(GearEvenAct::try_from(Gear::from(v)), Ok(v));
        }
        assert_eq!(GearOddReq::try_from(Gear::G1), Ok(GearOddReq::G1));
        assert_eq!(GearOddReq::G5 as u8, 5);
        assert!(GearOddReq::try_from(Gear::G2).is_err());
        assert!(GearOddAct::try_from(Gear::R).is_err());
        assert!(GearEvenReq::try_from(Gear::G3).is_err());
        assert_eq!(GearEvenReq::try_from(Gear::R), Ok(GearEvenReq::R));
        assert_eq!(GearEvenReq::try_from(Gear::N), Ok(GearEvenReq::N));
    }

    #[test]
    fn serde_by_code_or_label() {
        #[derive(serde::Deserialize, serde::Serialize)]
        struct C {
            g: Gear,
        }
        let c: C = toml::from_str("g = 7").unwrap();
        assert_eq!(c.g, Gear::R);
        let c: C = toml::from_str("g = \"G3\"").unwrap();
        assert_eq!(c.g, Gear::G3);
        assert_eq!(toml::to_string(&C { g: Gear::G5 }).unwrap().trim(), "g = 5");
        for bad in ["g = 8", "g = 2.5", "g = \"G7\"", "g = -1"] {
            let e = toml::from_str::<C>(bad).err().expect(bad).to_string();
            assert!(e.contains("gear"), "{bad}: {e}");
        }
    }
}

//! The one way every configuration file checks its numbers (issue 12): serde derives the
//! structure (tables, keys, types, unknown and missing keys), and each table declares the allowed
//! range of its numeric keys once, with [`ranges!`](crate::ranges!) — `key: [min, max]`, where a
//! bound may name another key of the same table (`over_temp_limit_c: [s.over_temp_warn_c,
//! 400.0]`). A value passes when it is finite and inside the closed range, so NaN and ±inf fail
//! every range (a plain `v < min || v > max` test lets NaN through). Optional keys are checked
//! when present, arrays element by element (`shift.up_kmh_0[2]`).
//!
//! The error is a [`RangeError`] naming the dotted key; the loader that holds the text places it
//! at the key's line ([`crate::toml_key::line_of`]) in its file. Cross-key rules that are not
//! ranges (a curve strictly increasing, a time step dividing the cycle) stay beside the table
//! they belong to, each an error naming its key.
//!
//! Written here rather than taken from a validation crate (garde, validator): their float range
//! rules compare with `<`/`>`, which NaN passes, and neither places an error at a TOML line.

/// A number outside its declared range (or not finite).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{key}` = {value} is out of its allowed range {min} ..= {max}")]
pub struct RangeError {
    /// The dotted key (`table.key`, `table.key[i]` for an array element).
    pub key: String,
    /// The value found.
    pub value: f64,
    /// Smallest allowed value.
    pub min: f64,
    /// Largest allowed value.
    pub max: f64,
}

impl RangeError {
    /// The error without its key, for a loader that names the key itself:
    /// `3 is outside 0 ..= 1`.
    pub fn reason(&self) -> String {
        format!("{} is outside {} ..= {}", self.value, self.min, self.max)
    }
}

/// True when `v` is finite and inside `min ..= max`.
pub fn within(v: f64, min: f64, max: f64) -> bool {
    v.is_finite() && v >= min && v <= max
}

/// A value a range applies to: a number, an optional number, or an array of them.
pub trait Bounded {
    /// Calls `f` with each number (with its index inside an array) until `f` fails.
    fn each(
        &self,
        f: &mut dyn FnMut(Option<usize>, f64) -> Result<(), RangeError>,
    ) -> Result<(), RangeError>;
}

macro_rules! bounded_number {
    ($($t:ty),*) => {$(
        impl Bounded for $t {
            fn each(
                &self,
                f: &mut dyn FnMut(Option<usize>, f64) -> Result<(), RangeError>,
            ) -> Result<(), RangeError> {
                #[allow(clippy::cast_precision_loss)]
                f(None, *self as f64)
            }
        }
    )*};
}
bounded_number!(f64, u8, u16, u32, u64, usize);

impl<T: Bounded> Bounded for Option<T> {
    fn each(
        &self,
        f: &mut dyn FnMut(Option<usize>, f64) -> Result<(), RangeError>,
    ) -> Result<(), RangeError> {
        self.as_ref().map_or(Ok(()), |v| v.each(f))
    }
}

impl Bounded for [f64] {
    fn each(
        &self,
        f: &mut dyn FnMut(Option<usize>, f64) -> Result<(), RangeError>,
    ) -> Result<(), RangeError> {
        self.iter()
            .enumerate()
            .try_for_each(|(i, v)| f(Some(i), *v))
    }
}

impl<const N: usize> Bounded for [f64; N] {
    fn each(
        &self,
        f: &mut dyn FnMut(Option<usize>, f64) -> Result<(), RangeError>,
    ) -> Result<(), RangeError> {
        self.as_slice().each(f)
    }
}

impl Bounded for Vec<f64> {
    fn each(
        &self,
        f: &mut dyn FnMut(Option<usize>, f64) -> Result<(), RangeError>,
    ) -> Result<(), RangeError> {
        self.as_slice().each(f)
    }
}

/// Checks one key: `table.key` (or `key` when `table` is empty) against `min ..= max`.
pub fn check<B: Bounded + ?Sized>(
    table: &str,
    key: &str,
    value: &B,
    min: f64,
    max: f64,
) -> Result<(), RangeError> {
    value.each(&mut |i, v| {
        if within(v, min, max) {
            return Ok(());
        }
        let dotted = if table.is_empty() {
            key.to_string()
        } else {
            format!("{table}.{key}")
        };
        Err(RangeError {
            key: match i {
                Some(i) => format!("{dotted}[{i}]"),
                None => dotted,
            },
            value: v,
            min,
            max,
        })
    })
}

/// A configuration table whose numeric keys have declared ranges.
pub(crate) trait Ranged {
    /// The table's name in its file (`""` for keys at the top level).
    const TABLE: &'static str;
    /// Checks every declared range, in declaration order; the first failure is returned.
    fn check_ranges(&self) -> Result<(), RangeError> {
        self.check_ranges_in(Self::TABLE)
    }
    /// [`Ranged::check_ranges`] with the keys under `table` (an element of an array of tables:
    /// `faults[2]`).
    fn check_ranges_in(&self, table: &str) -> Result<(), RangeError>;
}

/// Declares the ranges of a serde table: `ranges!(Type as s, "table" { key: [min, max], ... })`.
/// `s` names the table's value inside the bounds, for a bound that depends on another key.
#[macro_export]
macro_rules! ranges {
    ($ty:ty as $s:ident, $table:literal { $( $field:ident : [$min:expr, $max:expr] ),* $(,)? }) => {
        impl $crate::ranges::Ranged for $ty {
            const TABLE: &'static str = $table;
            fn check_ranges_in(
                &self,
                table: &str,
            ) -> ::std::result::Result<(), $crate::ranges::RangeError> {
                #[allow(unused_variables)]
                let $s = self;
                $( $crate::ranges::check(table, stringify!($field), &$s.$field, $min, $max)?; )*
                Ok(())
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Table {
        low: f64,
        high: f64,
        count: u32,
        start: Option<f64>,
        curve: [f64; 3],
    }

    crate::ranges!(Table as t, "table" {
        low: [0.0, 10.0],
        high: [t.low, 10.0],
        count: [1.0, 5.0],
        start: [-1.0, 1.0],
        curve: [0.0, 100.0],
    });

    fn good() -> Table {
        Table {
            low: 1.0,
            high: 2.0,
            count: 3,
            start: None,
            curve: [0.0, 50.0, 100.0],
        }
    }

    fn key_of(t: &Table) -> Option<String> {
        t.check_ranges().err().map(|e| e.key)
    }

    #[test]
    fn every_declared_range_is_checked_and_names_its_key() {
        assert_eq!(key_of(&good()), None);
        assert_eq!(
            key_of(&Table {
                low: -0.5,
                ..good()
            })
            .as_deref(),
            Some("table.low")
        );
        // A bound that names another key of the table.
        assert_eq!(
            key_of(&Table {
                high: 0.5,
                ..good()
            })
            .as_deref(),
            Some("table.high")
        );
        assert_eq!(
            key_of(&Table { count: 0, ..good() }).as_deref(),
            Some("table.count")
        );
        // An optional key is checked when present.
        assert_eq!(
            key_of(&Table {
                start: Some(2.0),
                ..good()
            })
            .as_deref(),
            Some("table.start")
        );
        // An array element by element.
        assert_eq!(
            key_of(&Table {
                curve: [0.0, 101.0, 5.0],
                ..good()
            })
            .as_deref(),
            Some("table.curve[1]")
        );
        // Under another table (an element of an array of tables).
        let e = Table { count: 9, ..good() }
            .check_ranges_in("t[2]")
            .unwrap_err();
        assert_eq!(e.key, "t[2].count");
    }

    #[test]
    fn nan_and_infinities_fail_every_range() {
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let e = Table { low: bad, ..good() }.check_ranges().unwrap_err();
            assert_eq!(e.key, "table.low");
            assert!(e.value.is_nan() || e.value == bad);
            let e = check("", "x", &bad, f64::NEG_INFINITY, f64::INFINITY).unwrap_err();
            assert_eq!(e.key, "x");
        }
        assert_eq!(
            RangeError {
                key: "a.b".into(),
                value: 3.0,
                min: 0.0,
                max: 1.0
            }
            .to_string(),
            "`a.b` = 3 is out of its allowed range 0 ..= 1"
        );
    }
}

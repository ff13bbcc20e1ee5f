//! Gears of the dual-clutch transmission (paper §2, Fig. 1): six forward gears, the odd ones on
//! input shaft 1 (clutch 1) and the even ones and reverse on input shaft 2 (clutch 2), and
//! neutral. The overall ratio of a gear enters the driveline's coupling ω_c = k·ω_out (eq. 3).
//!
//! A gear is a type, not a number: the bus codes of the DBC's value tables are converted at the
//! boundary (`crate::can::gear`), where an unknown code or a gear on the wrong shaft is an error.

/// A gear, or neutral (no gear engaged on a shaft, or no gear transmitting).
/// On the bus, in configs and reports a gear is its code in the DBC's value tables (serde in
/// `crate::can::gear`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Gear {
    #[default]
    N,
    G1,
    G2,
    G3,
    G4,
    G5,
    G6,
    R,
}

/// The forward gears, lowest first.
pub(crate) const FORWARD: [Gear; 6] = [Gear::G1, Gear::G2, Gear::G3, Gear::G4, Gear::G5, Gear::G6];

impl Gear {
    /// Forward gear `n` (1–6); `None` for any other number.
    pub fn forward(n: u8) -> Option<Gear> {
        FORWARD.get(usize::from(n).checked_sub(1)?).copied()
    }

    /// The number of a forward gear (1–6); `None` for neutral and reverse.
    pub fn number(self) -> Option<u8> {
        FORWARD
            .iter()
            .position(|g| *g == self)
            .and_then(|i| u8::try_from(i + 1).ok())
    }

    /// The input shaft the gear is on: `Some(0)` odd gears (clutch 1), `Some(1)` even gears and
    /// reverse (clutch 2), `None` for neutral.
    pub fn shaft(self) -> Option<usize> {
        match self {
            Gear::N => None,
            Gear::G1 | Gear::G3 | Gear::G5 => Some(0),
            Gear::G2 | Gear::G4 | Gear::G6 | Gear::R => Some(1),
        }
    }

    /// The next forward gear up (`None` from 6th, neutral or reverse).
    pub fn up(self) -> Option<Gear> {
        Gear::forward(self.number()? + 1)
    }

    /// The next forward gear down (`None` from 1st, neutral or reverse).
    pub fn down(self) -> Option<Gear> {
        Gear::forward(self.number()?.checked_sub(1)?)
    }

    /// Whether this is a forward gear above `other` (both forward).
    pub fn above(self, other: Gear) -> bool {
        matches!((self.number(), other.number()), (Some(a), Some(b)) if a > b)
    }

    /// Whether this is reverse.
    pub fn is_reverse(self) -> bool {
        self == Gear::R
    }
}

impl std::fmt::Display for Gear {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // `pad`: a width or alignment in the format string applies.
        match self.number() {
            Some(n) => f.pad(&n.to_string()),
            None if self.is_reverse() => f.pad("R"),
            None => f.pad("N"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_shafts_and_steps() {
        for n in 1..=6u8 {
            let g = Gear::forward(n).unwrap();
            assert_eq!(g.number(), Some(n));
            assert_eq!(g.shaft(), Some(usize::from(1 - n % 2)), "{g}");
        }
        assert_eq!(Gear::forward(0), None);
        assert_eq!(Gear::forward(7), None);
        assert_eq!(Gear::R.shaft(), Some(1));
        assert_eq!(Gear::N.shaft(), None);
        assert_eq!(Gear::G6.up(), None);
        assert_eq!(Gear::G1.down(), None);
        assert_eq!(Gear::G3.up(), Some(Gear::G4));
        assert_eq!(Gear::G3.down(), Some(Gear::G2));
        assert_eq!(Gear::R.up(), None);
        assert!(Gear::G4.above(Gear::G3));
        assert!(
            !Gear::R.above(Gear::G6),
            "reverse is not above a forward gear"
        );
        assert!(!Gear::G1.above(Gear::N));
        assert_eq!(
            [Gear::N, Gear::G2, Gear::R].map(|g| g.to_string()),
            ["N", "2", "R"]
        );
        assert_eq!(format!("{:>3}|{:<2}|", Gear::G1, Gear::R), "  1|R |");
    }
}

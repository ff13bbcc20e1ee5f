//! What a class's magnitude is measured over ([`Basis`]).

/// The unit of a multiplier's magnitude.
pub const RELATIVE: &str = "relative";

/// What a class's magnitude is measured over: the one definition per class that the truth
/// generator's curves (src/truth/curve.rs) are read by, each side computing it from its own model.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Basis {
    /// The term's change from `from` to `to` of its variable: the training records' 2 and 98 %
    /// quantiles of it, where the data pin the fitted shape down.
    Change { from: f64, to: f64 },
    /// A multiplier's relative change from `from` to `to` (its quantiles, as for `Change`): the
    /// term is a factor 1 + s of μ or of the spring load, and its magnitude
    /// (1 + s(to))/(1 + s(from)) − 1 reads the same whatever level the factor multiplies.
    Ratio { from: f64, to: f64 },
    /// The term's value of largest size over `from`…`to` of its variable, with its sign (a
    /// reading error over a fixed range of the channel).
    Largest { from: f64, to: f64 },
    /// The term's value at `at` of its variable.
    At { at: f64 },
    /// A parameter of the class's member (a time, a factor), as is.
    Parameter,
}

impl Basis {
    pub fn as_str(&self) -> &'static str {
        match self {
            Basis::Change { .. } => "change",
            Basis::Ratio { .. } => "ratio",
            Basis::Largest { .. } => "largest",
            Basis::At { .. } => "at",
            Basis::Parameter => "parameter",
        }
    }

    /// The variable's range (`at` for both ends of a point), `None` for a parameter.
    pub fn range(&self) -> Option<(f64, f64)> {
        match *self {
            Basis::Change { from, to }
            | Basis::Ratio { from, to }
            | Basis::Largest { from, to } => Some((from, to)),
            Basis::At { at } => Some((at, at)),
            Basis::Parameter => None,
        }
    }
}

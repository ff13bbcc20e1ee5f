//! What the records offer a class: the knots of its variable over the training records
//! ([`Knots`]), the channels it needs ([`Needs`], asked through [`Has`]), and which form of it
//! is fitted ([`Form`]).

use crate::gap::model::class::Variable;
use crate::gap::model::shape::KNOTS;
use std::collections::BTreeMap;

/// Knot positions of the class variables over the training records (variables that do not
/// vary have none: their classes cannot be checked).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Knots(pub BTreeMap<Variable, [f64; KNOTS]>);

/// What a class needs from the records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Needs {
    Torque,
    Temperatures,
    Requests,
    Engine,
}

/// Which representation of a class is fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Form {
    /// The flexible term (diagnosis).
    Flexible,
    /// The library member's parametric form (the calibration the TCU and the plant read).
    Member,
}

/// What the records can show of a class: `has` answers which channels they log.
pub type Has<'a> = &'a dyn Fn(Needs) -> bool;

//! The diagnosis's method ([`diagnose`]), in the order it runs: the records prepared and their noise floors ([`context`]), where the gap lies ([`where_`]), the recalibration and the greedy class selection ([`select`]), which recalibration parameters the records determine ([`identifiable`]), the black-box discrepancy ([`blackbox`]), the magnitudes' form error ([`form_error`]) and the typed findings ([`finding`]).
//! The paper's parameter identification, a method of its own (`ddct identify`), is
//! [`crate::identify`].

pub mod blackbox;
pub mod context;
pub mod diagnose;
pub mod finding;
pub mod form_error;
pub mod identifiable;
pub mod select;
pub mod where_;

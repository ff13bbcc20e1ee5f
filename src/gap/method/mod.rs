//! The method, in the order it runs: the paper's identification (§4, [`identify`]); the diagnosis ([`diagnose`]): the records prepared and their noise floors ([`context`]), where the gap lies ([`where_`]), the recalibration and the greedy class selection ([`select`]), the black-box discrepancy ([`blackbox`]), the magnitudes' form error ([`form_error`]) and the typed findings ([`finding`]).

pub mod blackbox;
pub mod context;
pub mod diagnose;
pub mod finding;
pub mod form_error;
pub mod identify;
pub mod select;
pub mod where_;

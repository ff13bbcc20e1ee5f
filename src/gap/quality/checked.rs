//! The channels the data-quality stage checks: the outputs the diagnosis compares (clutch
//! torques of (13), the thermocouples of (16), the positions, the engine torque of (18a)) and
//! the speeds it takes as inputs.

use crate::records::dataset::Col;

/// The channels checked.
pub const CHECKED: [Col; 11] = [
    Col::T1,
    Col::T2,
    Col::Pp1,
    Col::Pp2,
    Col::Cd,
    Col::X1,
    Col::X2,
    Col::Te,
    Col::Wf,
    Col::Wc1,
    Col::Wc2,
];

//! The 8-point Gauss–Legendre rule on [−1, 1] (nodes symmetric about 0, so the positive half
//! and its weights), shared by the clutch's radius integrals ([`super::clutch`]) and the
//! universal slip integral's table ([`super::slip_integral`]).

/// Gauss–Legendre nodes (positive half) on [−1, 1], 8-point rule.
pub(super) const GL_X: [f64; 4] = [
    0.960_289_856_497_536_3,
    0.796_666_477_413_626_8,
    0.525_532_409_916_329,
    0.183_434_642_495_649_8,
];
/// Gauss–Legendre weights matching [`GL_X`].
pub(super) const GL_W: [f64; 4] = [
    0.101_228_536_290_376_18,
    0.222_381_034_453_374_45,
    0.313_706_645_877_887_4,
    0.362_683_783_378_362,
];

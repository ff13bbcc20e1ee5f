//! The model the diagnosis fits: a candidate [`candidate::Model`] (parameters, library effects, class [`terms`]) and the channels it is compared on, the bounded shapes of the flexible terms ([`shape`]), the effect classes' vocabulary ([`class`]) and how each is fitted ([`classes`]: one `EffectClass` impl per family), the fittable parameters typed ([`keys`]).

pub mod candidate;
pub mod class;
pub mod classes;
pub mod keys;
pub mod shape;
pub mod terms;

//! How each effect class is fitted (issue 17 item 1; issue 43): one [`EffectClass`] impl per
//! family of classes, registered in `ClassId::fit` ([`registry`]). An impl says which channels
//! the class is fitted on, its free parameters with bounds (the increments of a bounded shape in
//! the class's variable, or the few physical parameters of a library member), how a parameter
//! vector sets a model and how it is removed again, and what its magnitude is measured over
//! ([`Basis`]). Bounds are physical limits, not plausible ranges: a fitted magnitude outside the
//! documented range is reported, not rejected (item 8).
//!
//! Where the classes enter the paper's model is in `gap::model::class` (equations (4)–(6), (9),
//! (10), (11), (16), (18a)); the families: [`friction`] (μ multipliers of (4)–(6), the
//! facing-surface temperature), [`factor`] (a factor in θ_c on μ_s of (4) or on the spring load
//! of (10): [`friction::STATIC_TEMPERATURE`], [`spring::SPRING_TEMPERATURE`]), [`kiss_point`]
//! ((9)), [`actuator`], [`thermal`] (the paths of (16)), [`engine`] ((18a)), [`sensors`]
//! (torque, thermocouples, position), [`speed_sensor`] (the speed channels) and [`member_only`] (the facings of (11), the backlash).
//!
//! Adding a class: a variant in `gap::model::class`'s table, one impl (a new file, or a struct in
//! its family's file), one line in [`registry`]; the trait's required methods are what the
//! compiler asks for.

pub mod actuator;
pub mod basis;
pub mod common;
pub mod effect_class;
pub mod engine;
pub mod factor;
pub mod friction;
pub mod interval;
pub mod kiss_point;
pub mod knots;
pub mod member_only;
pub mod registry;
pub mod sensors;
pub mod speed_sensor;
pub mod spring;
pub mod thermal;

pub use basis::{Basis, RELATIVE};
pub use common::{group_channels, zigzag_sign};
pub use effect_class::EffectClass;
pub use interval::magnitude_ci95;
pub use knots::{Form, Has, Knots, Needs};
pub use registry::conflicts;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::model::candidate::Model;
    use crate::gap::model::class::ClassId;

    #[test]
    fn every_class_is_registered_under_its_own_id() {
        for c in ClassId::ALL {
            assert_eq!(c.fit().id(), *c);
        }
    }

    /// Fits seen on the cases of `scripts/gap-cases`: a friction change over the clamp load
    /// whose first segment jumps (one turn: kept), a static-friction change fitted as a zigzag
    /// in the temperature (four turns: refitted rising), kiss-point wear whose small early
    /// increments are rounding beside the step at the end (two turns among the rest).
    #[test]
    fn zigzag_sign_counts_only_the_turns_that_matter() {
        let clamp = [0.0382, -0.0055, -0.0052, -0.0080, -0.0073, -0.0064];
        assert_eq!(zigzag_sign(&clamp), None);
        let static_friction = [0.0089, 0.0134, -0.0357, 0.0547, -0.0150, 0.0461];
        assert_eq!(zigzag_sign(&static_friction), Some(1.0));
        let wear = [-9e-5, 3.0e-4, -8.1e-4, 3.8e-3, -9.6e-3, 0.0899];
        assert_eq!(zigzag_sign(&wear), Some(1.0));
        assert_eq!(zigzag_sign(&[-0.1, -0.2, 0.001, -0.3]), None);
        assert_eq!(zigzag_sign(&[0.0; 6]), None);
    }

    #[test]
    fn every_shape_class_has_its_increments_in_its_parameters() {
        let base = Model::nominal(crate::model::params::Params::default());
        for c in ClassId::ALL {
            if let Some(r) = c.fit().increments() {
                let p = c.fit().params(&base);
                assert!(r.end <= p.len(), "{c:?}");
                for s in &p[r] {
                    assert!(s.name.contains(".d"), "{c:?}: {}", s.name);
                }
            }
        }
    }

    /// Only the two kiss-point classes share a term.
    #[test]
    fn the_kiss_point_classes_conflict_and_no_others() {
        use ClassId::*;
        assert!(conflicts(KissPointTemperature, KissPointEnergy));
        assert!(conflicts(SpringTemperature, SpringTemperature));
        assert!(!conflicts(FrictionTemperature, FrictionSlip));
    }
}

//! An injected effect's term as a curve over the physical variable it acts on, written beside
//! the truth (`truth.json`'s `curves`) so that a magnitude the diagnosis states over a range of
//! its own choosing (the change of the term between the training records' 2 and 98 % quantiles
//! of its variable, or a reading error over a fixed range) can be read off the truth by the same
//! definition. Computed from the truth's own forms and z-mappings ([`super::inject`]), never
//! from the diagnosis's terms: what a fleet report compares stays independent.
//!
//! The terms: friction multipliers (1 + a·f(z)) of μ in (13) give the relative change of μ;
//! kiss-point shifts of (9) give mm; a sensor's or the actuator transfer's reading error
//! e(v) = read(v) − v gives the channel's unit.

use super::inject::{self, Effect, Target};
use crate::gap::model::class::ClassId;

/// Points per curve.
const POINTS: usize = 161;

/// An effect's term over its variable.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Curve {
    pub class: ClassId,
    /// The physical variable, named as the diagnosis's [`crate::gap::model::class::Variable`] is.
    pub variable: &'static str,
    /// Unit of the variable.
    pub variable_unit: &'static str,
    /// What the term's value is, and its unit.
    pub term: &'static str,
    /// (variable, term) from the lowest to the highest value of the variable's grid.
    pub points: Vec<(f64, f64)>,
}

/// The curve of `e` where its class acts through one physical variable the diagnosis also
/// reports on; `None` for scalar effects and outside forms.
pub fn curve(e: &Effect) -> Option<Curve> {
    let Target::Class(class) = e.target else {
        return None;
    };
    let Grid {
        variable,
        variable_unit,
        term,
        lo,
        hi,
        z,
    } = grid(class)?;
    let reading = z
        .is_none()
        .then(|| inject::reading_reference(class))
        .flatten()
        .map(|(v0, v_ref)| e.reading_error(v0, v_ref));
    let value = |x: f64| -> f64 {
        match (z, &reading) {
            (Some(z), _) => e.term(z(x)),
            (None, Some(r)) => r.read(x) - x,
            (None, None) => 0.0,
        }
    };
    let points = (0..POINTS)
        .map(|k| {
            let x = lo + (hi - lo) * k as f64 / (POINTS - 1) as f64;
            (x, value(x))
        })
        .collect();
    Some(Curve {
        class,
        variable,
        variable_unit,
        term,
        points,
    })
}

/// Where a class's curve is drawn: its variable (name, unit), what the term is, the grid's
/// ends, and the variable's z-mapping for a term of (13) or (9) (`None` for a reading error).
struct Grid {
    variable: &'static str,
    variable_unit: &'static str,
    term: &'static str,
    lo: f64,
    hi: f64,
    z: ZMap,
}

/// A variable's z-mapping, `None` for a reading error.
type ZMap = Option<fn(f64) -> f64>;

/// The [`Grid`] of `class`; `None` for a class without a curve.
fn grid(class: ClassId) -> Option<Grid> {
    use ClassId as C;
    // The variable's z-mapping for a term of (13) or (9) (energies in MJ here, J in the truth's
    // z); `None` for a reading error.
    let energy: fn(f64) -> f64 = |mj| inject::z_energy(mj * 1e6);
    let (variable, variable_unit, term, lo, hi, z): (_, _, _, f64, f64, ZMap) = match class {
        C::FrictionTemperature | C::FrictionStaticTemperature => (
            "temperature",
            "°C",
            "relative change of μ",
            0.0,
            400.0,
            Some(inject::z_temp),
        ),
        C::FrictionSlip => (
            "slip",
            "rad/s",
            "relative change of μ",
            0.0,
            400.0,
            Some(inject::z_slip),
        ),
        C::FrictionClampLoad => (
            "clamp_load",
            "N",
            "relative change of μ",
            0.0,
            9000.0,
            Some(inject::z_clamp),
        ),
        C::FrictionEnergy => (
            "friction_energy",
            "MJ",
            "relative change of μ",
            0.0,
            4.0,
            Some(energy),
        ),
        C::KissPointTemperature => (
            "temperature",
            "°C",
            "kiss-point shift, mm",
            0.0,
            400.0,
            Some(inject::z_temp),
        ),
        C::KissPointEnergy => (
            "friction_energy",
            "MJ",
            "kiss-point shift, mm",
            0.0,
            4.0,
            Some(energy),
        ),
        C::SensorTorque => (
            "measurement",
            "N·m",
            "reading error, N·m",
            -100.0,
            300.0,
            None,
        ),
        C::SensorTemperature => ("measurement", "°C", "reading error, K", 0.0, 400.0, None),
        C::SensorPosition => ("measurement", "mm", "reading error, mm", 0.0, 9.0, None),
        C::ActuatorTransfer => (
            "position",
            "mm",
            "bearing minus measured position, mm",
            0.0,
            9.0,
            None,
        ),
        _ => return None,
    };
    Some(Grid {
        variable,
        variable_unit,
        term,
        lo,
        hi,
        z,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::truth::form::Family;
    use crate::truth::rng::Xoshiro;

    #[test]
    fn a_curve_is_the_term_the_truths_simulator_applies() {
        let mut rng = Xoshiro::new(7);
        let e = Effect::draw(
            Target::Class(ClassId::KissPointEnergy),
            Some(Family::Saturating),
            Some(0.2),
            &mut rng,
        );
        let c = curve(&e).unwrap();
        assert_eq!(c.variable, "friction_energy");
        // z = E / 1.2 MJ: at 1.2 MJ the saturating term reaches its magnitude (anchored at 0).
        let at = |x: f64| c.points.iter().find(|p| (p.0 - x).abs() < 1e-9).unwrap().1;
        assert_eq!(at(0.0), e.term(0.0));
        assert!((at(1.2) - e.term(1.0)).abs() < 1e-12);
        assert!(
            (e.term(1.0) - e.term(0.0) - 0.2).abs() < 1e-9,
            "{}",
            e.term(1.0)
        );
    }

    #[test]
    fn a_sensor_curve_is_its_reading_error() {
        let mut rng = Xoshiro::new(3);
        let e = Effect::draw(
            Target::Class(ClassId::SensorTorque),
            Some(Family::PiecewiseLinear),
            Some(2.0),
            &mut rng,
        );
        let c = curve(&e).unwrap();
        let (v0, v_ref) = inject::reading_reference(ClassId::SensorTorque).unwrap();
        let r = e.reading_error(v0, v_ref);
        for (x, y) in &c.points {
            assert_eq!(*y, r.read(*x) - *x);
        }
        assert_eq!(
            curve(&Effect::draw(
                Target::Class(ClassId::ActuatorLag),
                None,
                Some(2.0),
                &mut rng
            )),
            None
        );
    }
}

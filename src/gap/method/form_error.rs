//! The model-form part of a fitted magnitude's interval.
//!
//! The delta method ([`crate::gap::model::classes::magnitude_ci95`]) holds the noise of the records: the
//! spread the magnitude would show over repeated records of the same rig. It does not hold the
//! error of the form itself — a piecewise-linear shape on seven knots for a power law, a
//! straight gain and offset for a bent sensor characteristic, the disk temperature of (16)
//! replayed from the recalibrated thermal parameters as the variable of a friction fade — which
//! repeats on every record and so shifts the magnitude by more than its noise: on a 200-log
//! fleet a kiss-point wear fitted 1–2 % off with a ±1 % interval, a fade 2–8 % off with ±1.5 %.
//!
//! The records say how well the form fits: what the diagnosed model still leaves above the
//! noise floor on the class's channels (`left`, the validation's Σz² − n there) against what
//! the class closed (`closed`, the validation gain in Σz²). Their ratio is the share of the
//! effect's squared size the model does not reproduce, and its square root the effect's
//! relative error in amplitude; the magnitude is taken to be known no better than that, as one
//! standard deviation of a model-form error added in quadrature to the noise's. A model that
//! reproduces the validation records to the noise floor adds nothing.

use crate::gap::fit::lsq::Z95;

/// The relative standard deviation of a magnitude's model-form error: √(left/closed), 0 when
/// nothing is left above the floor or the class closed nothing.
pub fn relative(left: f64, closed: f64) -> f64 {
    if left > 0.0 && closed > 0.0 {
        (left / closed).sqrt()
    } else {
        0.0
    }
}

/// The 95 % interval `ci` of a magnitude `mag` (from the noise) widened by a model-form error of
/// relative standard deviation `rel`: the half-widths added in quadrature on each side.
pub fn widen(mag: f64, ci: (f64, f64), rel: f64) -> (f64, f64) {
    let form = Z95 * rel * mag.abs();
    let lo = (mag - ci.0).max(0.0).hypot(form);
    let hi = (ci.1 - mag).max(0.0).hypot(form);
    (mag - lo, mag + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nothing_left_above_the_floor_adds_nothing() {
        assert_eq!(relative(0.0, 50.0), 0.0);
        assert_eq!(relative(-3.0, 50.0), 0.0);
        assert_eq!(widen(0.2, (0.19, 0.215), 0.0), (0.19, 0.215));
    }

    #[test]
    fn the_form_error_adds_in_quadrature_to_each_side() {
        // 1 % of the closed Σz² left: a 10 % amplitude error, 1.96 × 0.1 × 0.5 = 0.098 at 95 %.
        let rel = relative(1.0, 100.0);
        assert!((rel - 0.1).abs() < 1e-15);
        let (lo, hi) = widen(-0.5, (-0.53, -0.48), rel);
        let form = Z95 * 0.05;
        assert!((-0.5 - lo - 0.03f64.hypot(form)).abs() < 1e-12);
        assert!((hi + 0.5 - 0.02f64.hypot(form)).abs() < 1e-12);
        // Wider on both sides, and by less than the two half-widths summed.
        assert!(lo < -0.53 && hi > -0.48 && -0.5 - lo < 0.03 + form);
    }
}

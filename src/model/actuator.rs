//! Clutch actuators: the throwout-bearing position follows its request as a first-order lag with
//! a rate limit, ẋ = sat_{±rate}((sat_{[x_min, x_max]}(x_ref) − x)/τ) (DESIGN.md §4).

use super::params::ActuatorParams;

/// Request clamped to the actuator range (mm); a non-finite request holds `x_mm`.
#[inline]
pub(crate) fn clamp_request(p: &ActuatorParams, x_ref_mm: f64, x_mm: f64) -> f64 {
    if x_ref_mm.is_finite() {
        x_ref_mm.clamp(p.x_min_mm, p.x_max_mm)
    } else {
        x_mm
    }
}

/// Position rate (mm/s) of one actuator at position `x_mm` with request `x_ref_mm`.
#[inline]
pub fn derivative(p: &ActuatorParams, x_mm: f64, x_ref_mm: f64) -> f64 {
    let r = clamp_request(p, x_ref_mm, x_mm);
    ((r - x_mm) / p.tau_s).clamp(-p.rate_mm_per_s, p.rate_mm_per_s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Params;

    #[test]
    fn lag_and_rate_limit() {
        let p = Params::default().actuator;
        // Small error: linear lag, 0.5 mm / 20 ms = 25 mm/s.
        assert!((derivative(&p, 1.0, 1.5) - 25.0).abs() < 1e-12);
        // Large error: rate limited.
        assert_eq!(derivative(&p, 0.0, 8.0), 100.0);
        assert_eq!(derivative(&p, 8.0, 0.0), -100.0);
        // Out-of-range request is clamped to the range.
        assert_eq!(clamp_request(&p, 12.0, 3.0), 8.0);
        assert_eq!(clamp_request(&p, f64::NAN, 3.0), 3.0);
    }
}

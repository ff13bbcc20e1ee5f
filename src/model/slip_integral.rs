//! The slip dependence of the equivalent friction radius (6) in closed form over one universal,
//! tabulated function (issue 14: the plant's step at its true cost).
//!
//! With x = γ|ω| and the substitution y = xρ, the slip-dependent part of (6),
//! Q(ω) = 1/(R2−R1)·∫_{R1}^{R2} tanh(γρ|ω|)^{1/3} ρ dρ, is exactly
//!
//!   Q(ω) = (P(x·R2) − P(x·R1)) / ((R2 − R1)·x²),   P(Y) = ∫_0^Y y·tanh(y)^{1/3} dy,
//!
//! and P does not depend on any parameter. P(Y) = f(Y)·Y^{7/3} with f smooth and even
//! (f(0) = 3/7, f(Y) = 3/7 − Y²/39 + O(Y⁴)); f is tabulated once on [0, [`Y_SAT`]] with its
//! exact derivative f′ = (t − 7f/3)/Y, t(y) = (tanh y / y)^{1/3}, and interpolated by cubic
//! Hermite polynomials: the interpolation error is at most h⁴/384·max|f⁽⁴⁾| ≈ 1e-10 for the
//! table's step h = Y_SAT/[`N`] (checked against the 8-node quadrature of `clutch` and a
//! 512-panel reference in the tests). Beyond Y_SAT, tanh(y)^{1/3} = 1 to within 1e-19, so
//! P(Y) = P(Y_SAT) + (Y² − Y_SAT²)/2 exactly to double precision.
//!
//! One evaluation costs two cube roots and two table lookups, against eight `tanh` and eight
//! cube roots for the 8-node rule.

use super::gauss_legendre::{GL_W, GL_X};
use std::sync::LazyLock;

/// Upper end of the table: tanh(22)^{1/3} differs from 1 by less than 1e-19.
pub const Y_SAT: f64 = 22.0;
/// Number of table intervals.
pub const N: usize = 2048;
const H: f64 = Y_SAT / N as f64;

/// f and f′ at the knots Y_k = k·H, and P(Y_SAT).
struct Table {
    f: Vec<f64>,
    df: Vec<f64>,
    p_sat: f64,
}

/// t(y) = (tanh y / y)^{1/3}, smooth and even, t(0) = 1.
fn t(y: f64) -> f64 {
    if y.abs() < 1e-4 {
        // tanh y / y = 1 − y²/3 + O(y⁴); its cube root 1 − y²/9 + O(y⁴).
        1.0 - y * y / 9.0
    } else {
        (y.tanh() / y).cbrt()
    }
}

/// ∫ over [a, b] of y·tanh(y)^{1/3} dy, taken in s = y^{1/3} where the integrand
/// 3s⁶·t(s³) is smooth down to zero.
fn panel(a: f64, b: f64) -> f64 {
    let (sa, sb) = (a.cbrt(), b.cbrt());
    let (mid, half) = (0.5 * (sa + sb), 0.5 * (sb - sa));
    let g = |s: f64| 3.0 * s.powi(6) * t(s * s * s);
    let mut sum = 0.0;
    for i in 0..4 {
        sum += GL_W[i] * (g(mid + half * GL_X[i]) + g(mid - half * GL_X[i]));
    }
    half * sum
}

static TABLE: LazyLock<Table> = LazyLock::new(|| {
    let mut f = vec![3.0 / 7.0; N + 1];
    let mut df = vec![0.0; N + 1];
    let mut p = 0.0;
    for k in 1..=N {
        let (a, b) = ((k - 1) as f64 * H, k as f64 * H);
        // One 8-node panel per interval: in s = y^{1/3} the integrand is a smooth function
        // whose degree-15 Taylor remainder over a width of 0.01 is below round-off.
        p += panel(a, b);
        let y7 = b * b * b.cbrt();
        f[k] = p / y7;
        df[k] = (t(b) - 7.0 / 3.0 * f[k]) / b;
    }
    Table { f, df, p_sat: p }
});

/// The interpolant of [`p`] per table interval k, as the cubic a0 + s·(a1 + s·(a2 + s·a3)) in the
/// local coordinate s = Y/H − k ∈ [0, 1] (the Hermite form of [`p`] expanded once: one 32-byte
/// record per lookup, four multiply-adds), for the batch torque of
/// [`super::clutch_batch`].
pub(crate) type Cubic = [f64; 4];

static CUBICS: LazyLock<Box<[Cubic; N]>> = LazyLock::new(|| {
    let tab = &*TABLE;
    let mut c = Box::new([[0.0; 4]; N]);
    for (k, ck) in c.iter_mut().enumerate() {
        let (f0, f1) = (tab.f[k], tab.f[k + 1]);
        let (d0, d1) = (H * tab.df[k], H * tab.df[k + 1]);
        *ck = [
            f0,
            d0,
            3.0 * (f1 - f0) - 2.0 * d0 - d1,
            2.0 * (f0 - f1) + d0 + d1,
        ];
    }
    c
});

/// The per-interval cubics of f (P(Y) = f(Y)·Y^{7/3}) for Y in [0, [`Y_SAT`]], interval k
/// covering [k·H, (k+1)·H] with H = Y_SAT/[`N`].
pub(crate) fn cubics() -> &'static [Cubic; N] {
    &CUBICS
}

/// P(Y_SAT) − Y_SAT²/2: beyond saturation P(Y) = this + Y²/2.
pub(crate) fn p_sat_offset() -> f64 {
    TABLE.p_sat - 0.5 * Y_SAT * Y_SAT
}

/// P(Y) = ∫_0^Y y·tanh(y)^{1/3} dy for Y ≥ 0.
#[inline]
pub fn p(y: f64) -> f64 {
    let tab = &*TABLE;
    if y >= Y_SAT {
        return tab.p_sat + 0.5 * (y - Y_SAT) * (y + Y_SAT);
    }
    let u = y / H;
    let k = (u as usize).min(N - 1);
    let s = u - k as f64;
    // Cubic Hermite basis on [Y_k, Y_k+1] in the local coordinate s ∈ [0, 1].
    let (s2, s3) = (s * s, s * s * s);
    let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
    let h10 = s3 - 2.0 * s2 + s;
    let h01 = -2.0 * s3 + 3.0 * s2;
    let h11 = s3 - s2;
    let f = h00 * tab.f[k] + h10 * H * tab.df[k] + h01 * tab.f[k + 1] + h11 * H * tab.df[k + 1];
    f * y * y * y.cbrt()
}

/// Below this x = γ|ω| (1/m), [`q`] takes the leading term of P at zero: x² and P(xR) would leave
/// the normal range further down (the quotient became 0/0 near x = 1e-160).
pub const X_TINY: f64 = 1e-60;
/// Above this x, [`q`] is its saturated value (R1 + R2)/2: x² would overflow further up.
pub const X_HUGE: f64 = 1e60;

/// True when the closed form [`q`] applies to the facing `r1 < r2` (m): not for a facing so
/// narrow ((R2−R1)/(R2+R1) < 2 %) that the difference of P would lose digits. A NaN radius
/// compares as neither: false as well.
#[inline]
pub fn closed_form_applies(r1: f64, r2: f64) -> bool {
    matches!(
        (r2 - r1).partial_cmp(&(0.02 * (r2 + r1))),
        Some(std::cmp::Ordering::Greater | std::cmp::Ordering::Equal)
    )
}

/// Q(ω) of (6) for radii `r1 < r2` (m) and x = γ|ω| (1/m): the closed form above. Falls back to
/// `None` when [`closed_form_applies`] is false; the caller then integrates directly.
///
/// At the ends of the range of x the quotient is taken in the form that stays in range: below
/// [`X_TINY`], P(Y) = 3/7·Y^{7/3} to double precision (the next term is 7Y²/117 relative), so
/// Q = 3/7·x^{1/3}·(R2^{7/3} − R1^{7/3})/(R2 − R1); above [`X_HUGE`] both ends are saturated and
/// Q = (R2² − R1²)/(2(R2 − R1)) = (R1 + R2)/2 exactly.
#[inline]
pub fn q(r1: f64, r2: f64, x: f64) -> Option<f64> {
    if !closed_form_applies(r1, r2) {
        return None;
    }
    if x == 0.0 {
        return Some(0.0);
    }
    if x < X_TINY {
        let r73 = |r: f64| r * r * r.cbrt();
        return Some(3.0 / 7.0 * x.cbrt() * (r73(r2) - r73(r1)) / (r2 - r1));
    }
    if x > X_HUGE {
        return Some(0.5 * (r1 + r2));
    }
    Some((p(x * r2) - p(x * r1)) / ((r2 - r1) * x * x))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// P against a direct, independent fine rule in y (1 M midpoint panels, away from the
    /// y^{4/3} corner at 0) and against its closed form beyond saturation.
    #[test]
    fn p_matches_direct_integration() {
        for &y in &[0.05f64, 0.3, 1.0, 2.7, 7.5, 15.0, 21.9, 30.0, 400.0] {
            let n = 1_000_000;
            let h = y / n as f64;
            let direct: f64 = (0..n)
                .map(|i| {
                    let v = (i as f64 + 0.5) * h;
                    v * v.tanh().cbrt() * h
                })
                .sum();
            let rel = (p(y) - direct).abs() / direct;
            assert!(rel < 1e-8, "P({y}) = {} vs {direct}: {rel:e}", p(y));
        }
    }

    /// The series at zero: P(Y) = 3/7·Y^{7/3}·(1 − 7Y²/117 + …).
    #[test]
    fn p_small_argument_series() {
        for &y in &[1e-6f64, 1e-3, 0.01] {
            let series = 3.0 / 7.0 * y * y * y.cbrt() * (1.0 - 7.0 * y * y / 117.0);
            assert!((p(y) - series).abs() <= 1e-9 * series, "{y}");
        }
        assert_eq!(p(0.0), 0.0);
    }

    /// The interpolation error between knots (mid-points, the worst place for Hermite) is below
    /// the h⁴/384·max|f⁽⁴⁾| bound stated in the module doc: checked by re-integrating exactly.
    #[test]
    fn interpolation_error_between_knots() {
        let mut worst: f64 = 0.0;
        for k in (0..N).step_by(37) {
            let y = (k as f64 + 0.5) * H;
            let exact = (0..k)
                .map(|j| sub(j as f64 * H, (j + 1) as f64 * H))
                .sum::<f64>()
                + sub(k as f64 * H, y);
            worst = worst.max((p(y) - exact).abs() / exact);
        }
        assert!(worst < 1e-9, "worst relative interpolation error {worst:e}");
        // The exact value: four 8-node panels per interval.
        fn sub(a: f64, b: f64) -> f64 {
            (0..4)
                .map(|j| {
                    panel(
                        a + (b - a) * j as f64 / 4.0,
                        a + (b - a) * (j + 1) as f64 / 4.0,
                    )
                })
                .sum()
        }
    }

    /// The ends of the range of x: finite, and continuous with the quotient across
    /// [`X_TINY`] and [`X_HUGE`] (it gave 0/0 = NaN for x below about 1e-160 before).
    #[test]
    fn q_at_extreme_slips() {
        let (r1, r2) = (0.075, 0.115);
        let at = |x: f64| q(r1, r2, x).unwrap();
        for x in [
            f64::MIN_POSITIVE,
            1e-300,
            1e-170,
            1e-100,
            1e100,
            1e300,
            f64::MAX,
        ] {
            assert!(at(x).is_finite() && at(x) >= 0.0, "q({x:e}) = {}", at(x));
        }
        assert!(at(5e-324) >= 0.0 && at(5e-324) < 1e-100);
        for (lo, hi) in [
            (X_TINY * (1.0 - 1e-15), X_TINY * (1.0 + 1e-15)),
            (X_HUGE * (1.0 - 1e-15), X_HUGE * (1.0 + 1e-15)),
        ] {
            let (a, b) = (at(lo), at(hi));
            assert!((a - b).abs() <= 1e-13 * b, "{lo:e}: {a} vs {b}");
        }
        assert_eq!(at(1e300), 0.5 * (r1 + r2));
    }

    /// The expanded cubics give the Hermite interpolant of [`p`]: f·Y^{7/3} within round-off of
    /// P across and between the knots, and the offset gives P beyond saturation.
    #[test]
    fn cubics_reproduce_p() {
        let c = cubics();
        let mut worst: f64 = 0.0;
        for i in 1..=20_000 {
            let y = Y_SAT * i as f64 / 20_000.0 * (1.0 - 1e-12);
            let k = ((y / H) as usize).min(N - 1);
            let s = y / H - k as f64;
            let [a0, a1, a2, a3] = c[k];
            let f = a0 + s * (a1 + s * (a2 + s * a3));
            worst = worst.max((f * y * y * y.cbrt() - p(y)).abs() / p(y));
        }
        assert!(worst < 1e-14, "worst relative difference {worst:e}");
        let y = 40.0;
        assert!((p_sat_offset() + 0.5 * y * y - p(y)).abs() <= 1e-13 * p(y));
    }

    #[test]
    fn narrow_facings_fall_back() {
        assert!(q(0.1, 0.101, 5.0).is_none());
        assert_eq!(q(0.075, 0.115, 0.0), Some(0.0));
        // Fully saturated: Q = (R1 + R2)/2.
        let v = q(0.075, 0.115, 1e4).unwrap();
        assert!((v - 0.095).abs() < 1e-15, "{v}");
    }
}

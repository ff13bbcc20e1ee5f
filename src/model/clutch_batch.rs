//! Single-clutch torque (13) over many points at once (issue 14: vectorised torque), the same
//! function as [`super::clutch::torque`] written so that the compiler vectorises it.
//!
//! Per point (structure of arrays: bearing positions, slips, temperatures, one output):
//! - the flat-spring load F(u_fs(x_to, θ)) of (7)–(10), clamped with min/max;
//! - the dynamic friction coefficient μ_d(θ) = c1·sin(c2θ + c3) + c4 of (4)/(5), the sine as a
//!   polynomial after a Cody–Waite reduction by π (within 2 ulp of `f64::sin`);
//! - the equivalent friction radius (6) R_μ = μ_s(R1+R2)/2 + (μ_d − μ_s)·Q with Q over the
//!   universal integral P of [`super::slip_integral`]: Q = (P(xR2) − P(xR1))/((R2 − R1)·x²),
//!   x = γ|ω|, each P(xR)/x² taken as f(xR)·R^{7/3}·x^{1/3} from the table's cubics (two gathers)
//!   below Y_SAT and as (P(Y_SAT) − Y_SAT²/2)·x⁻² + R²/2 above it, selected without a branch;
//!   x^{1/3} from a rough inverse cube root (exponent bit trick, one Newton step of order 4)
//!   and one exact-residual correction (within 0.51 ulp of the true cube root and 1 ulp of
//!   `f64::cbrt`), x⁻² from one division;
//! - T = sign(ω)·2·R_μ·F of (13), 0 where F = 0 or ω = 0 (a select, not an early return).
//!
//! No libm call and no branch in the loop. The few points outside the range the polynomials
//! are written for (|c2θ + c3| > [`ARG_MAX`] rad, x = γ|ω| outside [[`X_MIN`], [`X_MAX`]] for a
//! non-zero slip, or a non-finite slip or temperature) are flagged per chunk and recomputed by
//! the scalar [`super::clutch::torque`], so every input gives what the scalar function gives;
//! a facing too narrow for the closed form of Q is handed to the scalar function entirely.
//! The batch agrees with the scalar function to about 1e-15 relative (1e-12 relative, or
//! absolute below 1 N·m, checked in the tests over dense grids and random points; up to 5e-13
//! only where R_μ nearly vanishes, μ_d(θ) ≈ 0 at full sliding, which magnifies the sine's last
//! bit).
//!
//! On x86-64 the loop is compiled twice: for the baseline target (SSE2, 2 lanes) and, chosen at
//! run time when the processor has them, with AVX2 and FMA (4 lanes, fused multiply-adds in
//! the polynomials).

use super::clutch;
use super::params::ClutchParams;
use super::slip_integral::{self, Cubic, N, Y_SAT};

/// Largest |c2θ + c3| (rad) the sine reduction is written for (k·π split exactly for |k| < 2^20);
/// the model's temperatures and coefficients give at most 410 rad.
pub const ARG_MAX: f64 = 1e5;
/// Smallest x = γ|ω| (1/m) of the vectorised slip integral (below it the scalar series).
pub const X_MIN: f64 = slip_integral::X_TINY;
/// Largest x = γ|ω| (1/m) of the vectorised slip integral (above it the scalar limit).
pub const X_MAX: f64 = slip_integral::X_HUGE;

/// Points per chunk: the unit of the out-of-range check and of the scalar recomputation.
const CHUNK: usize = 512;

/// Errors of [`torque_batch`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum BatchError {
    #[error(
        "torque batch: slices of unequal length (x_to_mm {x_to_mm}, slip_radps {slip_radps}, \
         theta_c {theta_c}, out {out})"
    )]
    LengthMismatch {
        x_to_mm: usize,
        slip_radps: usize,
        theta_c: usize,
        out: usize,
    },
}

/// Single-clutch torque (13) (N·m) at every point: `out[i] = torque(p, x_to_mm[i],
/// slip_radps[i], theta_c[i])` to within 1e-12 relative (absolute below 1 N·m). The four
/// slices must have the same length (else [`BatchError::LengthMismatch`] and `out` is left as
/// it was). Uses AVX2 and FMA when the processor has them, else the baseline code of
/// [`torque_batch_portable`].
pub fn torque_batch(
    p: &ClutchParams,
    x_to_mm: &[f64],
    slip_radps: &[f64],
    theta_c: &[f64],
    out: &mut [f64],
) -> Result<(), BatchError> {
    #[cfg(target_arch = "x86_64")]
    if slip_integral::closed_form_applies(p.r1_m, p.r2_m)
        && std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
    {
        check_lengths(x_to_mm, slip_radps, theta_c, out)?;
        // SAFETY: `run_avx2_fma` only needs the processor to support AVX2 and FMA, which was
        // just checked at run time; it is otherwise safe code (slices, no raw pointers).
        unsafe { run_avx2_fma(p, &Consts::new(p), x_to_mm, slip_radps, theta_c, out) };
        return Ok(());
    }
    torque_batch_portable(p, x_to_mm, slip_radps, theta_c, out)
}

/// [`torque_batch`] without the run-time dispatch: the code compiled for the baseline target
/// (on x86-64: SSE2, two lanes, no fused multiply-add). For benchmarks and tests.
pub fn torque_batch_portable(
    p: &ClutchParams,
    x_to_mm: &[f64],
    slip_radps: &[f64],
    theta_c: &[f64],
    out: &mut [f64],
) -> Result<(), BatchError> {
    batch_in::<Plain>(p, x_to_mm, slip_radps, theta_c, out)
}

/// The batch in the arithmetic `A`: lengths checked, a facing too narrow for the closed form
/// computed point by point by [`torque`](super::clutch::torque).
fn batch_in<A: Arith>(
    p: &ClutchParams,
    x: &[f64],
    w: &[f64],
    th: &[f64],
    out: &mut [f64],
) -> Result<(), BatchError> {
    check_lengths(x, w, th, out)?;
    if !slip_integral::closed_form_applies(p.r1_m, p.r2_m) {
        scalar(p, x, w, th, out);
        return Ok(());
    }
    run::<A>(p, &Consts::new(p), x, w, th, out);
    Ok(())
}

fn check_lengths(x: &[f64], w: &[f64], th: &[f64], out: &[f64]) -> Result<(), BatchError> {
    let n = out.len();
    if x.len() == n && w.len() == n && th.len() == n {
        Ok(())
    } else {
        Err(BatchError::LengthMismatch {
            x_to_mm: x.len(),
            slip_radps: w.len(),
            theta_c: th.len(),
            out: n,
        })
    }
}

/// The scalar function at every point (equal lengths checked by the caller).
fn scalar(p: &ClutchParams, x: &[f64], w: &[f64], th: &[f64], out: &mut [f64]) {
    for (i, o) in out.iter_mut().enumerate() {
        *o = clutch::torque(p, x[i], w[i], th[i]);
    }
}

/// The loop compiled with AVX2 and FMA enabled.
///
/// # Safety
/// The processor must support AVX2 and FMA (checked with `is_x86_feature_detected!`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn run_avx2_fma(
    p: &ClutchParams,
    k: &Consts,
    x: &[f64],
    w: &[f64],
    th: &[f64],
    out: &mut [f64],
) {
    run::<Fused>(p, k, x, w, th, out);
}

/// Chunk by chunk: the vectorised kernel, then the scalar function where it flagged a point.
#[inline(always)]
fn run<A: Arith>(p: &ClutchParams, k: &Consts, x: &[f64], w: &[f64], th: &[f64], out: &mut [f64]) {
    let tab = slip_integral::cubics();
    for (c, o) in out.chunks_mut(CHUNK).enumerate() {
        let r = c * CHUNK..c * CHUNK + o.len();
        let (x, w, th) = (&x[r.clone()], &w[r.clone()], &th[r]);
        if kernel::<A>(k, tab, x, w, th, o) {
            for i in 0..o.len() {
                if needs_scalar(k, w[i], th[i]) {
                    o[i] = clutch::torque(p, x[i], w[i], th[i]);
                }
            }
        }
    }
}

/// The branch-free loop over one chunk; true when a point needs the scalar function.
#[inline(always)]
fn kernel<A: Arith>(
    k: &Consts,
    tab: &[Cubic; N],
    x: &[f64],
    w: &[f64],
    th: &[f64],
    out: &mut [f64],
) -> bool {
    let n = out.len();
    let (x, w, th) = (&x[..n], &w[..n], &th[..n]);
    let mut flagged = false;
    for i in 0..n {
        out[i] = point::<A>(k, tab, x[i], w[i], th[i]);
        flagged |= needs_scalar(k, w[i], th[i]);
    }
    flagged
}

/// True outside the range the vectorised sine and slip integral are written for.
#[inline(always)]
fn needs_scalar(k: &Consts, slip: f64, theta: f64) -> bool {
    let arg = k.c2 * theta + k.c3;
    let w = slip.abs();
    let x = k.gamma * w;
    let arg_ok = (-ARG_MAX..=ARG_MAX).contains(&arg);
    let x_ok = (w == 0.0) | (X_MIN..=X_MAX).contains(&x);
    !(arg_ok & x_ok)
}

/// Torque (13) at one point, valid where [`needs_scalar`] is false.
#[inline(always)]
fn point<A: Arith>(k: &Consts, tab: &[Cubic; N], x_to: f64, slip: f64, theta: f64) -> f64 {
    let force = clamp_force::<A>(k, x_to, theta);
    // 2·(μ_d − μ_s) and 2·R_μ (the factor 2 of (13) in the constants).
    let mu_excess2 = A::madd(
        k.c1_2,
        sin_reduced::<A>(k.c2 * theta + k.c3),
        k.c4_less_mu_s_2,
    );
    let q = slip_shape::<A>(k, tab, k.gamma * slip.abs());
    let r_mu2 = A::madd(mu_excess2, q, k.mu_s_rm_2);
    let t = (r_mu2 * force).copysign(slip);
    if (force == 0.0) | (slip == 0.0) {
        0.0
    } else {
        t
    }
}

/// F(u_fs(x_to, θ)) of (7)–(10) (N), as [`clutch::normal_force`] (λ in m per mm);
/// NaN compressions clamp to 0 as `f64::max` does there.
#[inline(always)]
fn clamp_force<A: Arith>(k: &Consts, x_to: f64, theta: f64) -> f64 {
    let d = theta - k.theta_a;
    // As (9) is written in `clutch::x_isp`: x_to − x0 cancels near the kiss point.
    let x0 = k.x_isp2 * d * d + k.x_isp1 * d + k.x_isp0;
    // Compressions in m.
    let u = k.lambda_m * (x_to - x0);
    let u_max = k.lambda_m * (k.x_to_max - x0);
    let hi = if u_max > 0.0 { u_max } else { 0.0 };
    let lo = if u > 0.0 { u } else { 0.0 };
    let u = if lo < hi { lo } else { hi };
    A::madd(A::madd(k.p3, u, k.p2), u, k.p1) * u
}

/// Q(ω) of (6) for x = γ|ω| in [X_MIN, X_MAX]: (P(xR2) − P(xR1))/((R2 − R1)·x²).
#[inline(always)]
fn slip_shape<A: Arith>(k: &Consts, tab: &[Cubic; N], x: f64) -> f64 {
    let (c, inv_x2) = cbrt_and_inv_square::<A>(x);
    p_over_x2::<A>(k, &k.outer, tab, x, c, inv_x2) - p_over_x2::<A>(k, &k.inner, tab, x, c, inv_x2)
}

/// P(xR)/((R2 − R1)·x²) for one facing radius R: f(xR)·R^{7/3}·x^{1/3}/(R2 − R1) below Y_SAT,
/// else ((P(Y_SAT) − Y_SAT²/2)·x⁻² + R²/2)/(R2 − R1); both computed, one selected.
#[inline(always)]
fn p_over_x2<A: Arith>(
    k: &Consts,
    r: &Radius,
    tab: &[Cubic; N],
    x: f64,
    c: f64,
    inv_x2: f64,
) -> f64 {
    let y = x * r.r;
    let interpolated = f_interpolated::<A>(tab, y) * (c * r.r73);
    let saturated = A::madd(k.p_sat_offset, inv_x2, r.half_r_sq);
    if y >= Y_SAT {
        saturated
    } else {
        interpolated
    }
}

/// 1.5·2^52: adding and subtracting it rounds a double below 2^51 to the nearest integer, and
/// the low bits of the sum hold that integer.
const ROUND: f64 = 6_755_399_441_055_744.0;
const INV_H: f64 = N as f64 / Y_SAT;
const LAST_KNOT: f64 = (N - 1) as f64;

/// f(y) = P(y)/y^{7/3} from the table's cubic on the interval of y (clamped into the table;
/// garbage, but in bounds, for y ≥ Y_SAT or NaN).
#[inline(always)]
fn f_interpolated<A: Arith>(tab: &[Cubic; N], y: f64) -> f64 {
    let u = y * INV_H;
    let v = u - 0.5;
    let v = if v < LAST_KNOT { v } else { LAST_KNOT };
    let big = v + ROUND;
    let kf = big - ROUND;
    // The low bits of `big` are those of the integer (ROUND's are zero).
    let idx = big.to_bits() as usize & (N - 1);
    let s = u - kf;
    let [a0, a1, a2, a3] = tab[idx];
    A::madd(A::madd(A::madd(a3, s, a2), s, a1), s, a0)
}

/// π split for the reduction: PI_A and PI_B have 32 significant bits (k·PI_A and k·PI_B are
/// exact for |k| < 2^21), PI_C the rest (π − PI_A − PI_B − PI_C ≈ 2e-37).
const PI_A: f64 = 3.141_592_653_468_251_2;
const PI_B: f64 = 1.215_420_101_260_793_2e-10;
const PI_C: f64 = 4.044_532_497_591_901e-21;
/// h(z) = (sin(√z)/√z − 1)/z on [0, 2.4675] ⊃ [0, (π/2)²], degree 7: its Taylor series to
/// degree 15 economised exactly (rational arithmetic) in Chebyshev polynomials to degree 7,
/// truncation below 2e-18 on the interval.
const SIN_H: [f64; 8] = [
    -0.166_666_666_666_666_66,
    0.008_333_333_333_333_316,
    -0.000_198_412_698_412_549_82,
    2.755_731_921_916_537e-6,
    -2.505_210_761_723_207_7e-8,
    1.605_897_732_582_191_7e-10,
    -7.643_970_670_958_955e-13,
    2.731_448_873_171_023e-15,
];

/// sin(a) for |a| ≤ ARG_MAX: a = kπ + r with |r| ≤ π/2 (a − k·PI_A is exact, the rest rounds
/// once per term), sin(a) = (−1)^k·sin(r), sin(r) = r + r·z·h(z), z = r².
#[inline(always)]
pub(crate) fn sin_reduced<A: Arith>(a: f64) -> f64 {
    let big = a * std::f64::consts::FRAC_1_PI + ROUND;
    let kf = big - ROUND;
    let odd = big.to_bits() << 63;
    let r = A::madd(-kf, PI_C, A::madd(-kf, PI_B, A::madd(-kf, PI_A, a)));
    let z = r * r;
    let mut h = SIN_H[7];
    for &c in SIN_H[..7].iter().rev() {
        h = A::madd(h, z, c);
    }
    let s = A::madd(r * z, h, r);
    f64::from_bits(s.to_bits() ^ odd)
}

/// Bias of the inverse-cube-root bit trick on the high word (fitted: |1 − x·r0³| ≤ 0.126).
const INV_CBRT_BIAS: f64 = 1_430_197_064.0;
const TWO52: f64 = 4_503_599_627_370_496.0;

/// x^{−1/3} for x in [X_MIN, X_MAX] within 4e-6: the high word of x divided by −3 plus a bias
/// (within 4.3 %), then one step of order 4 of r ← r·(1 − e)^{−1/3}, e = 1 − x·r³.
#[inline(always)]
fn inv_cbrt_rough<A: Arith>(x: f64) -> f64 {
    let hx = f64::from_bits(TWO52.to_bits() | (x.to_bits() >> 32)) - TWO52;
    // The integer nearest to t is in the low 32 bits of t + ROUND: the high word of r.
    let t = A::madd(hx, -1.0 / 3.0, INV_CBRT_BIAS) + ROUND;
    let r = f64::from_bits(t.to_bits() << 32);
    // (1 − e)^{−1/3} = 1 + e/3 + 2e²/9 + 14e³/81 + 35e⁴/243 + O(e⁵)
    let e = A::madd(-x, r * r * r, 1.0);
    let s = A::madd(
        A::madd(A::madd(35.0 / 243.0, e, 14.0 / 81.0), e, 2.0 / 9.0),
        e,
        1.0 / 3.0,
    );
    A::madd(r * e, s, r)
}

/// (x^{1/3}, x⁻²) for x in [X_MIN, X_MAX]. The cube root: t = x·r² cut to 17 significant bits,
/// so t³ and the residual d = x − t³ are exact, then x^{1/3} = t·(1 − δ)^{−1/3}, δ = d/x
/// (|δ| < 1e-4), to three terms: within 0.51 ulp. One division gives 1/x for δ and x⁻².
#[inline(always)]
pub(crate) fn cbrt_and_inv_square<A: Arith>(x: f64) -> (f64, f64) {
    let r = inv_cbrt_rough::<A>(x);
    let t = f64::from_bits((x * (r * r)).to_bits() & 0xFFFF_FFF0_0000_0000);
    let inv_x = 1.0 / x;
    let delta = (x - t * t * t) * inv_x;
    let s = A::madd(A::madd(14.0 / 81.0, delta, 2.0 / 9.0), delta, 1.0 / 3.0);
    (A::madd(t * delta, s, t), inv_x * inv_x)
}

/// Multiply-add as two roundings (baseline) or one (FMA).
pub(crate) trait Arith {
    fn madd(a: f64, b: f64, c: f64) -> f64;
}

/// a·b + c, two roundings: what the baseline target vectorises.
pub(crate) struct Plain;

impl Arith for Plain {
    #[inline(always)]
    fn madd(a: f64, b: f64, c: f64) -> f64 {
        a * b + c
    }
}

/// fma(a, b, c): one instruction only where FMA is enabled (else a libm call).
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) struct Fused;

impl Arith for Fused {
    #[inline(always)]
    fn madd(a: f64, b: f64, c: f64) -> f64 {
        a.mul_add(b, c)
    }
}

/// One facing radius R in the form (6) uses it, all divided by R2 − R1.
struct Radius {
    r: f64,
    /// R^{7/3}/(R2 − R1).
    r73: f64,
    /// R²/(2(R2 − R1)).
    half_r_sq: f64,
}

/// Everything per call: the parameters in the form the loop uses.
struct Consts {
    theta_a: f64,
    x_isp2: f64,
    x_isp1: f64,
    x_isp0: f64,
    /// λ·1e-3: compression in m per mm of bearing travel.
    lambda_m: f64,
    x_to_max: f64,
    p1: f64,
    p2: f64,
    p3: f64,
    /// 2·c1.
    c1_2: f64,
    c2: f64,
    c3: f64,
    /// 2·(c4 − μ_s).
    c4_less_mu_s_2: f64,
    /// 2·μ_s·(R1 + R2)/2.
    mu_s_rm_2: f64,
    gamma: f64,
    inner: Radius,
    outer: Radius,
    /// (P(Y_SAT) − Y_SAT²/2)/(R2 − R1).
    p_sat_offset: f64,
}

impl Consts {
    fn new(p: &ClutchParams) -> Consts {
        let dr = p.r2_m - p.r1_m;
        let radius = |r: f64| Radius {
            r,
            r73: r * r * r.cbrt() / dr,
            half_r_sq: 0.5 * r * r / dr,
        };
        Consts {
            theta_a: p.theta_a_c,
            x_isp2: p.x_isp2_mm_per_c2,
            x_isp1: p.x_isp1_mm_per_c,
            x_isp0: p.x_isp0_mm,
            lambda_m: p.lambda * 1e-3,
            x_to_max: p.x_to_max_mm,
            p1: p.p1_n_per_m,
            p2: p.p2_n_per_m2,
            p3: p.p3_n_per_m3,
            c1_2: 2.0 * p.c1,
            c2: p.c2_rad_per_c,
            c3: p.c3_rad,
            c4_less_mu_s_2: 2.0 * (p.c4 - p.mu_s),
            mu_s_rm_2: p.mu_s * (p.r1_m + p.r2_m),
            gamma: p.gamma_s_per_m,
            inner: radius(p.r1_m),
            outer: radius(p.r2_m),
            p_sat_offset: slip_integral::p_sat_offset() / dr,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Params;

    fn cp() -> ClutchParams {
        Params::default().clutch
    }

    /// SplitMix64: uniform doubles in [0, 1) for the random points.
    struct Uniform(u64);

    impl Uniform {
        fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// A non-zero finite double and its two neighbours (`f64::next_up` needs Rust 1.86).
    fn adjacent(a: f64) -> [f64; 3] {
        [
            f64::from_bits(a.to_bits() - 1),
            a,
            f64::from_bits(a.to_bits() + 1),
        ]
    }

    fn ulps(a: f64, reference: f64) -> f64 {
        (a - reference).abs() / (reference.abs() * f64::EPSILON).max(f64::MIN_POSITIVE)
    }

    /// The sine against `f64::sin`: within 3e-16 relative (2 ulp) over the model's arguments (|c2θ +
    /// c3| ≤ 410 rad), dense and at the doubles nearest to multiples of π, and within 1e-15 up to
    /// ARG_MAX; both arithmetics.
    #[test]
    fn sine_matches_std() {
        fn worst(f: fn(f64) -> f64, args: &[f64]) -> f64 {
            args.iter()
                .map(|&a| (f(a) - a.sin()).abs() / a.sin().abs())
                .fold(0.0, f64::max)
        }
        let model: Vec<f64> = (0..=2_000_000)
            .map(|i| -410.0 + 820.0 * i as f64 / 2e6)
            .chain((1..=131).flat_map(|k| adjacent(k as f64 * std::f64::consts::PI)))
            .chain((1..=131).flat_map(|k| adjacent(-k as f64 * std::f64::consts::PI)))
            .filter(|&a| a != 0.0)
            .collect();
        let mut u = Uniform(3);
        let wide: Vec<f64> = (0..1_000_000)
            .map(|_| ARG_MAX * (2.0 * u.next() - 1.0))
            .chain((1..31_830).map(|k| k as f64 * std::f64::consts::PI))
            .collect();
        for f in [sin_reduced::<Plain> as fn(f64) -> f64, sin_reduced::<Fused>] {
            let (m, w) = (worst(f, &model), worst(f, &wide));
            eprintln!("sine: worst relative difference {m:.2e} (model range), {w:.2e} (wide)");
            assert!(m <= 3e-16, "{m:e}");
            assert!(w <= 1e-15, "{w:e}");
        }
        assert_eq!(sin_reduced::<Plain>(0.0), 0.0);
    }

    /// |c³ − x| / (3x) in ulps of c, with the residual exact to about 1e-32 (fused multiply-adds).
    fn cbrt_error_ulps(c: f64, x: f64) -> f64 {
        let (sq, sq_lo) = (c * c, c.mul_add(c, -(c * c)));
        let (cube, cube_lo) = (c * sq, c.mul_add(sq, -(c * sq)));
        let residual = (cube - x) + cube_lo + c * sq_lo;
        (residual / (3.0 * x)).abs() / f64::EPSILON * 2.0f64.powi(c.log2().floor() as i32) / c
    }

    /// The cube root within 0.51 ulp of the true one and within 2 ulp of f64::cbrt; x⁻² within 4e-15; log-uniform over [X_MIN, X_MAX] and densely over three
    /// octaves.
    #[test]
    fn cube_root_matches_std() {
        let mut u = Uniform(5);
        let xs: Vec<f64> = (0..1_000_000)
            .map(|_| X_MIN * (X_MAX / X_MIN).powf(u.next()))
            .chain((0..=600_000).map(|i| 1.0 + 7.0 * i as f64 / 6e5))
            .chain([X_MIN, X_MAX, 1.0, 8.0, 27.0, 0.001])
            .collect();
        for f in [
            cbrt_and_inv_square::<Plain> as fn(f64) -> (f64, f64),
            cbrt_and_inv_square::<Fused>,
        ] {
            let (mut true_err, mut std_err, mut inv_err) = (0.0f64, 0.0f64, 0.0f64);
            for &x in &xs {
                let (c, inv_x2) = f(x);
                true_err = true_err.max(cbrt_error_ulps(c, x));
                std_err = std_err.max(ulps(c, x.cbrt()));
                inv_err = inv_err.max((inv_x2 * x * x - 1.0).abs());
            }
            eprintln!(
                "cube root: {true_err:.3} ulp from the true root, {std_err:.1} ulp from f64::cbrt; \
                 x^-2 within {inv_err:.1e}"
            );
            assert!(true_err <= 0.51, "{true_err}");
            assert!(std_err <= 2.0, "{std_err}");
            assert!(inv_err <= 4e-15, "{inv_err:e}");
        }
    }

    /// The batch paths under test: the dispatching one, the baseline one, and the fused
    /// arithmetic run directly (libm's fma where the processor lacks FMA: slow, but the same
    /// values), so both arithmetics are checked on any machine.
    fn paths() -> Vec<(&'static str, Batch)> {
        vec![
            ("dispatched", torque_batch as Batch),
            ("portable", torque_batch_portable),
            ("fused", batch_in::<Fused>),
        ]
    }

    type Batch = fn(&ClutchParams, &[f64], &[f64], &[f64], &mut [f64]) -> Result<(), BatchError>;

    /// The largest relative difference of every path from [`clutch::torque`] at the points
    /// (absolute below 1 N·m; NaN where the scalar is NaN, the same infinity where it is
    /// infinite), asserted within 1e-12.
    fn check(p: &ClutchParams, x: &[f64], w: &[f64], th: &[f64]) -> f64 {
        let mut worst: f64 = 0.0;
        for (name, batch) in paths() {
            let mut out = vec![f64::NAN; x.len()];
            batch(p, x, w, th, &mut out).unwrap();
            for i in 0..x.len() {
                let (a, b) = (out[i], clutch::torque(p, x[i], w[i], th[i]));
                if b.is_nan() {
                    assert!(
                        a.is_nan(),
                        "{name} at ({}, {}, {}): {a} vs NaN",
                        x[i],
                        w[i],
                        th[i]
                    );
                    continue;
                }
                if a == b {
                    continue;
                }
                let d = (a - b).abs() / b.abs().max(1.0);
                assert!(
                    d <= 1e-12,
                    "{name} at ({}, {}, {}): {a} vs {b}",
                    x[i],
                    w[i],
                    th[i]
                );
                worst = worst.max(d);
            }
        }
        worst
    }

    /// Every combination of the coordinates (a dense grid).
    fn grid(xs: &[f64], ws: &[f64], ths: &[f64]) -> [Vec<f64>; 3] {
        let mut g = [vec![], vec![], vec![]];
        for &x in xs {
            for &w in ws {
                for &th in ths {
                    g[0].push(x);
                    g[1].push(w);
                    g[2].push(th);
                }
            }
        }
        g
    }

    /// Slips from ±5e-324 to ±1e4 rad/s, log-spaced, with 0 and the ends of the vectorised range.
    fn slips() -> Vec<f64> {
        let mut ws = vec![
            0.0, -0.0, 5e-324, 1e-300, 1e-61, 1e-20, 1e-9, 1e4, 37.0, 200.0,
        ];
        ws.extend((0..=120).map(|i| 10f64.powf(-8.0 + 12.0 * i as f64 / 120.0)));
        let gammas = [X_MIN, X_MAX].map(|x| x / cp().gamma_s_per_m);
        ws.extend(gammas.iter().flat_map(|&w| adjacent(w)));
        ws.extend(ws.clone().iter().map(|w| -w));
        ws
    }

    /// Dense grid over x_to in [0, x_to,max] (and beyond), the slips above and θ across the
    /// valid range −40..400 °C (and beyond), for the nominal clutch.
    #[test]
    fn batch_matches_scalar_on_a_dense_grid() {
        let p = cp();
        let xs: Vec<f64> = (0..=40)
            .map(|i| p.x_to_max_mm * i as f64 / 40.0)
            .chain([-1.0, p.x_to_max_mm + 1.0])
            .collect();
        let ths: Vec<f64> = (0..=44)
            .map(|i| -40.0 + 10.0 * i as f64)
            .chain([-60.0, 600.0])
            .collect();
        let [x, w, th] = grid(&xs, &slips(), &ths);
        let worst = check(&p, &x, &w, &th);
        eprintln!(
            "dense grid ({} points): worst relative difference {worst:.2e}",
            x.len()
        );
    }

    /// Random points (x_to in [0, x_to,max], slip in [−1e4, 1e4] and log-uniform down to 1e-8,
    /// θ in [−40, 400]) for the nominal clutch and clutches across the parameter ranges.
    #[test]
    fn batch_matches_scalar_at_random_points() {
        let nominal = cp();
        let variants = [
            nominal,
            ClutchParams {
                c2_rad_per_c: -1.0,
                c3_rad: 10.0,
                c1: -1.0,
                c4: 1.0,
                ..nominal
            },
            ClutchParams {
                c2_rad_per_c: 1.0,
                c3_rad: -10.0,
                ..nominal
            },
            ClutchParams {
                gamma_s_per_m: 1e-3,
                ..nominal
            },
            ClutchParams {
                gamma_s_per_m: 1e3,
                ..nominal
            },
            ClutchParams {
                r1_m: 0.01,
                r2_m: 0.5,
                ..nominal
            },
            ClutchParams {
                r1_m: 0.2,
                r2_m: 0.21,
                ..nominal
            },
            ClutchParams {
                x_isp2_mm_per_c2: 1e-5,
                x_isp1_mm_per_c: -0.002,
                ..nominal
            },
        ];
        let mut u = Uniform(11);
        for p in variants {
            let n = 100_000;
            let x: Vec<f64> = (0..n).map(|_| p.x_to_max_mm * u.next()).collect();
            let w: Vec<f64> = (0..n)
                .map(|i| match i % 3 {
                    0 => 1e4 * (2.0 * u.next() - 1.0),
                    1 => {
                        10f64.powf(-8.0 + 12.0 * u.next()) * if u.next() < 0.5 { -1.0 } else { 1.0 }
                    }
                    _ => 400.0 * u.next() - 200.0,
                })
                .collect();
            let th: Vec<f64> = (0..n).map(|_| -40.0 + 440.0 * u.next()).collect();
            let worst = check(&p, &x, &w, &th);
            eprintln!(
                "random points, r = ({}, {}), γ = {}: worst relative difference {worst:.2e}",
                p.r1_m, p.r2_m, p.gamma_s_per_m
            );
        }
    }

    /// Non-finite and out-of-range inputs (handed to the scalar function) give what it gives,
    /// in any chunk position.
    #[test]
    fn batch_matches_scalar_on_odd_inputs() {
        let p = cp();
        let odd = [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e300,
            -1e300,
            0.0,
            5.5,
            150.0,
        ];
        let [x, w, th] = grid(&odd, &odd, &odd);
        // Shift the odd points across a chunk boundary among ordinary ones.
        let pad = |v: &[f64], fill: f64| {
            let mut out = vec![fill; CHUNK - 100];
            out.extend_from_slice(v);
            out
        };
        check(&p, &pad(&x, 5.5), &pad(&w, 40.0), &pad(&th, 90.0));
    }

    #[test]
    fn unequal_lengths_are_an_error_and_empty_is_fine() {
        let p = cp();
        let mut out = [7.0; 3];
        for (_, batch) in paths() {
            let e = batch(&p, &[1.0; 3], &[1.0; 2], &[1.0; 3], &mut out).unwrap_err();
            assert_eq!(
                e,
                BatchError::LengthMismatch {
                    x_to_mm: 3,
                    slip_radps: 2,
                    theta_c: 3,
                    out: 3
                }
            );
            assert_eq!(out, [7.0; 3]);
            assert!(batch(&p, &[1.0; 3], &[1.0; 3], &[1.0; 3], &mut out[..2]).is_err());
            batch(&p, &[], &[], &[], &mut []).unwrap();
        }
    }
}

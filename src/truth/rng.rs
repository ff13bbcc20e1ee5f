//! The truth generator's own seeded random numbers: xoshiro256** seeded through splitmix64,
//! normal deviates by Box–Muller. Independent of the diagnosis's own generator on purpose.

use rand_xoshiro::rand_core::{RngCore, SeedableRng};
use rand_xoshiro::Xoshiro256StarStar;

/// splitmix64 step: a good 64-bit mixer, used to seed and to derive sub-seeds.
#[inline]
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A seed derived from a seed and a sequence of labels (trial index, record number, …).
pub fn derive(seed: u64, labels: &[u64]) -> u64 {
    let mut s = seed ^ 0x5EED_7A11_0F7E_5EED;
    let mut out = splitmix64(&mut s);
    for l in labels {
        s ^= l.wrapping_mul(0xD6E8_FEB8_6659_FD93);
        out = splitmix64(&mut s) ^ out.rotate_left(17);
    }
    out
}

/// xoshiro256** seeded through SplitMix64 (the `rand_xoshiro` crate's generator and seeding),
/// with the draws the truths need.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Xoshiro {
    core: Xoshiro256StarStar,
    spare: Option<u64>,
}

impl Xoshiro {
    pub fn new(seed: u64) -> Self {
        Xoshiro {
            core: Xoshiro256StarStar::seed_from_u64(seed),
            spare: None,
        }
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.core.next_u64()
    }

    /// Uniform in [0, 1).
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    #[inline]
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Log-uniform in [lo, hi] (both > 0).
    pub fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        (lo.ln() + (hi.ln() - lo.ln()) * self.uniform()).exp()
    }

    /// Uniform integer in 0..n (n ≥ 1).
    pub fn below(&mut self, n: usize) -> usize {
        ((self.uniform() * n as f64) as usize).min(n.saturating_sub(1))
    }

    /// +1 or −1 with equal probability.
    pub fn sign(&mut self) -> f64 {
        if self.next_u64() >> 63 == 0 {
            1.0
        } else {
            -1.0
        }
    }

    /// Standard normal deviate (Box–Muller, the second deviate kept for the next call).
    pub fn normal(&mut self) -> f64 {
        if let Some(bits) = self.spare.take() {
            return f64::from_bits(bits);
        }
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (2.0 * std::f64::consts::PI * u2).sin_cos();
        self.spare = Some((r * s).to_bits());
        r * c
    }

    /// A seeded permutation of 0..n (Fisher–Yates).
    pub fn permutation(&mut self, n: usize) -> Vec<usize> {
        let mut v: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            let j = self.below(i + 1);
            v.swap(i, j);
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stream of xoshiro256** seeded through SplitMix64, computed independently (a python
    /// transcription of the reference C code): the seeded truths stay what they were.
    #[test]
    fn the_stream_is_the_reference_xoshiro256_star_star() {
        let mut r = Xoshiro::new(42);
        let got: Vec<u64> = (0..3).map(|_| r.next_u64()).collect();
        assert_eq!(
            got,
            [
                0x1578_0b2e_0c2e_c716,
                0x6104_d986_6d11_3a7e,
                0xae17_5332_39e4_99a1
            ]
        );
    }

    #[test]
    fn deterministic_and_well_spread() {
        let mut a = Xoshiro::new(7);
        let mut b = Xoshiro::new(7);
        for _ in 0..100 {
            assert_eq!(a.next_u64(), b.next_u64());
        }
        let mut r = Xoshiro::new(1);
        let n = 200_000;
        let (mut m, mut v) = (0.0, 0.0);
        for _ in 0..n {
            let x = r.normal();
            m += x;
            v += x * x;
        }
        m /= n as f64;
        v = v / n as f64 - m * m;
        assert!(m.abs() < 0.01 && (v - 1.0).abs() < 0.02, "{m} {v}");
        let u: f64 = (0..n).map(|_| r.uniform()).sum::<f64>() / n as f64;
        assert!((u - 0.5).abs() < 0.005);
        assert_ne!(derive(1, &[2, 3]), derive(1, &[3, 2]));
    }
}

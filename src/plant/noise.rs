//! Seeded sensor noise that does not depend on call order: the sample of channel `c` in cycle `k`
//! is a pure function of (seed, k, c) — SplitMix64 hashing into two uniforms, Box–Muller into a
//! standard normal. Two runs with the same seed see the same noise on the same cycle even if one
//! of them skipped or bunched cycles.

/// SplitMix64 finaliser.
#[inline]
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform number in (0, 1) from a 64-bit hash.
#[inline]
fn unit(h: u64) -> f64 {
    ((h >> 11) as f64 + 0.5) / (1u64 << 53) as f64
}

/// Standard normal sample of channel `channel` in cycle `cycle` for `seed`.
pub(crate) fn gauss(seed: u64, cycle: u64, channel: u32) -> f64 {
    let base = mix(seed ^ mix(cycle.wrapping_mul(0x1000_0000_01B3) ^ u64::from(channel)));
    let u1 = unit(mix(base));
    let u2 = unit(mix(base ^ 0xD1B5_4A32_D192_ED03));
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Uniform number in (0, 1) of channel `channel` for `seed` (for draws that need one).
pub fn uniform(seed: u64, index: u64, channel: u32) -> f64 {
    unit(mix(seed
        ^ mix(
            index.wrapping_mul(0x9E37_79B9) ^ (u64::from(channel) << 32)
        )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_normal_moments_and_determinism() {
        let n = 200_000u64;
        let (mut s, mut s2, mut s4) = (0.0, 0.0, 0.0);
        for k in 0..n {
            let x = gauss(7, k, 3);
            s += x;
            s2 += x * x;
            s4 += x * x * x * x;
        }
        let n = n as f64;
        let mean = s / n;
        let var = s2 / n - mean * mean;
        // Standard errors: mean 1/sqrt(n) = 0.0022, variance sqrt(2/n) = 0.0032, kurtosis ~0.011.
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.015, "var {var}");
        assert!((s4 / n - 3.0).abs() < 0.06, "4th moment {}", s4 / n);
        assert_eq!(gauss(7, 123, 3), gauss(7, 123, 3));
        assert_ne!(gauss(7, 123, 3), gauss(8, 123, 3));
        assert_ne!(gauss(7, 123, 3), gauss(7, 123, 4));
        // Neighbouring cycles are uncorrelated.
        let c: f64 = (0..100_000u64)
            .map(|k| gauss(1, k, 0) * gauss(1, k + 1, 0))
            .sum::<f64>()
            / 1e5;
        assert!(c.abs() < 0.015, "lag-1 correlation {c}");
    }
}

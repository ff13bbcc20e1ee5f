//! Number text appended to a byte buffer without `core::fmt`, byte for byte what Rust's
//! formatting prints, for output written by the million (`ddct log decode --format csv`): an
//! f64 as `{}` prints it, a microsecond time as `{:.6}` of its seconds, a CAN id as `0x{:03X}`.
//!
//! Every function keeps `core::fmt` for the cases its fast path does not cover, so the text is
//! the same for every input; the unit tests compare each against `format!`.

use std::io::Write as _;
use std::time::Duration;

/// 2^53: below it every integral f64 is exact as an i64 (and `{}` prints its digits).
const EXACT_INT: f64 = 9_007_199_254_740_992.0;

/// Appends `v` as `format!("{v}")` prints it: the shortest digits that read back to the same
/// f64, never in exponent notation. Integral values (counters, CRCs, gears, most speeds) go
/// through integer formatting, the others through zmij's shortest digits (the Schubfach
/// algorithm) where they are Rust's (see [`same_shortest_digits`]), `core::fmt` otherwise and
/// where zmij would use an exponent.
pub(crate) fn push_f64(out: &mut Vec<u8>, v: f64) {
    let i = v as i64;
    // −0.0 == 0.0 but prints "-0": it takes the general way.
    if i as f64 == v && v.abs() < EXACT_INT && (i != 0 || v.is_sign_positive()) {
        out.extend_from_slice(itoa::Buffer::new().format(i).as_bytes());
        return;
    }
    if v.is_finite() {
        let mut buf = zmij::Buffer::new();
        let s = buf.format_finite(v).as_bytes();
        if !s.contains(&b'e') && same_shortest_digits(v, s) {
            // zmij writes integral values with ".0" ("-0.0"); `{}` without.
            out.extend_from_slice(s.strip_suffix(b".0").unwrap_or(s));
            return;
        }
    }
    let _ = write!(out, "{v}");
}

/// Whether zmij's digits `s` of `v` are Rust's. Both print the shortest digits that read back
/// to `v`, the ones closest to it; they differ only on a tie, two shortest candidates exactly
/// as close (zmij takes the even one, Rust rounds up: 1000000000000000.25 prints as …0.2 and
/// …0.3). A tie needs `v` at the midpoint `(d + 1/2)·10^j` of candidates `d·10^j` within half
/// an ulp of it, so `d + 1/2 >= v / ulp >= 2^52`: 16 digits or more. And `v` must then be
/// exactly a decimal of at most 18 significant digits ending in 5, which a binary fraction of
/// more than 25 digits after the point never is (its decimal expansion has as many digits after
/// the point, the last a 5, and at most 30 % of them leading zeros).
fn same_shortest_digits(v: f64, s: &[u8]) -> bool {
    if binary_fraction_digits(v) > 25 {
        return true;
    }
    let digits = s.iter().filter(|c| c.is_ascii_digit()).count();
    let leading_zeros = s
        .iter()
        .take_while(|c| matches!(c, b'-' | b'0' | b'.'))
        .filter(|c| **c == b'0')
        .count();
    digits - leading_zeros <= 15
}

/// The number of binary digits after the point in the exact value of a finite `v` (0 for an
/// integer).
fn binary_fraction_digits(v: f64) -> u32 {
    let bits = v.to_bits();
    let biased = ((bits >> 52) & 0x7FF) as i32;
    let fraction = bits & ((1 << 52) - 1);
    // v = significand · 2^exponent
    let (significand, exponent) = match biased {
        0 => (fraction, -1074),
        _ => (fraction | 1 << 52, biased - 1075),
    };
    if significand == 0 {
        return 0;
    }
    let exponent = exponent + significand.trailing_zeros() as i32;
    exponent.min(0).unsigned_abs()
}

/// Seconds below which `{:.6}` of `Duration::as_secs_f64` is exactly the seconds and the six
/// digits of microseconds: up to 2^32 s the f64 is within 2^-21 s (< 0.5 µs) of the exact time.
const EXACT_SECS: u64 = 1 << 32;

/// Appends `t` as `format!("{:.6}", t.as_secs_f64())` prints it. A time on whole microseconds
/// (every candump time) before 2^32 s (the year 2106) is written from its integer seconds and
/// microseconds; any other through `core::fmt`.
pub(crate) fn push_secs_micros(out: &mut Vec<u8>, t: Duration) {
    let secs = t.as_secs();
    let nanos = t.subsec_nanos();
    if secs >= EXACT_SECS || nanos % 1000 != 0 {
        let _ = write!(out, "{:.6}", t.as_secs_f64());
        return;
    }
    out.extend_from_slice(itoa::Buffer::new().format(secs).as_bytes());
    out.push(b'.');
    push_padded(out, nanos / 1000, 6);
}

/// Appends `n` in decimal with leading zeros to `width` digits (`n` < 10^width).
fn push_padded(out: &mut Vec<u8>, mut n: u32, width: usize) {
    let start = out.len();
    out.resize(start + width, b'0');
    for slot in out[start..].iter_mut().rev() {
        *slot = b'0' + (n % 10) as u8;
        n /= 10;
    }
}

/// Appends `id` as `format!("0x{id:03X}")` prints it (upper-case hex, at least three digits).
pub(crate) fn push_hex_id(out: &mut Vec<u8>, id: u32) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    let digits = ((32 - id.leading_zeros()).div_ceil(4) as usize).max(3);
    out.extend_from_slice(b"0x");
    for k in (0..digits).rev() {
        out.push(HEX[((id >> (4 * k)) & 0xF) as usize]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// xorshift64*: a seeded stream of test inputs.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }
    }

    fn f64_text(v: f64) -> String {
        let mut out = Vec::new();
        push_f64(&mut out, v);
        String::from_utf8(out).unwrap()
    }

    fn check_f64(v: f64) {
        assert_eq!(f64_text(v), format!("{v}"), "bits {:#018x}", v.to_bits());
    }

    #[test]
    fn f64_edge_values_print_as_display() {
        let edges = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            -0.6000000000000001,
            0.1 + 0.2,
            0.003,
            1e-5,
            1e-6,
            1e-7,
            1.5e-7,
            123456.789e-12,
            1e15,
            1e16,
            1e17,
            1e21,
            1e22,
            1e23,
            1e300,
            EXACT_INT - 1.0,
            EXACT_INT,
            EXACT_INT + 2.0,
            -EXACT_INT,
            9.5e15,
            4.35e15 + 0.5,
            // Ties: two shortest candidates exactly as close (Rust rounds up).
            1e15 + 0.25,
            1e14 + 0.125,
            1e13 + 0.0625,
            1e12 + 0.03125,
            1e5 + 1.0 / 4096.0,
            -(1e9 + 1.0 / 256.0),
            i64::MAX as f64,
            i64::MIN as f64,
            u64::MAX as f64,
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            f64::EPSILON,
            f64::from_bits(1),
            f64::from_bits(0x000F_FFFF_FFFF_FFFF),
            -f64::from_bits(0x0008_0000_0000_0000),
            5e-324,
            f64::NAN,
            -f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            std::f64::consts::PI,
            -std::f64::consts::E,
        ];
        for v in edges {
            check_f64(v);
        }
        for e in -330..=310 {
            let p = 10f64.powi(e);
            for v in [
                p,
                -p,
                p * 1.5,
                p * 0.999_999_999_999_999_9,
                p + p * f64::EPSILON,
            ] {
                check_f64(v);
            }
        }
    }

    #[test]
    fn f64_dyadic_values_near_ties_print_as_display() {
        // Integers plus short binary fractions: the values whose exact decimal expansions are
        // short enough for ties.
        let mut rng = Rng(3);
        for _ in 0..200_000 {
            let int = (rng.next() >> (rng.next() % 64)) as f64;
            let frac_bits = (rng.next() % 30) as i32;
            let frac = (rng.next() % (1 << frac_bits)) as f64 / 2f64.powi(frac_bits);
            check_f64(int + frac);
            check_f64(-(int + frac));
        }
    }

    #[test]
    fn binary_fraction_digits_of_values() {
        assert_eq!(binary_fraction_digits(0.0), 0);
        assert_eq!(binary_fraction_digits(3.0), 0);
        assert_eq!(binary_fraction_digits(1e300), 0);
        assert_eq!(binary_fraction_digits(0.5), 1);
        assert_eq!(binary_fraction_digits(-2.75), 2);
        assert_eq!(binary_fraction_digits(1e15 + 0.25), 2);
        assert_eq!(binary_fraction_digits(f64::from_bits(1)), 1074);
        assert_eq!(binary_fraction_digits(0.1), 55);
    }

    #[test]
    fn f64_random_bit_patterns_print_as_display() {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        for _ in 0..300_000 {
            check_f64(f64::from_bits(rng.next()));
        }
    }

    #[test]
    fn f64_scaled_raw_values_print_as_display() {
        // Physical values as a DBC produces them: raw · factor + offset.
        let factors = [
            1.0,
            0.1,
            0.01,
            0.001,
            0.05,
            0.25,
            0.0625,
            0.125,
            1e-4,
            3.0517578125e-5,
        ];
        let offsets = [0.0, -40.0, -3276.8, -1e4, 0.5, -273.15];
        let mut rng = Rng(42);
        for _ in 0..200_000 {
            let raw = (rng.next() as i64) >> (rng.next() % 64);
            let f = factors[(rng.next() % factors.len() as u64) as usize];
            let o = offsets[(rng.next() % offsets.len() as u64) as usize];
            check_f64(raw as f64 * f + o);
            check_f64((rng.next() % 65_536) as f64 * f + o);
        }
    }

    fn time_text(t: Duration) -> String {
        let mut out = Vec::new();
        push_secs_micros(&mut out, t);
        String::from_utf8(out).unwrap()
    }

    fn check_time(t: Duration) {
        assert_eq!(time_text(t), format!("{:.6}", t.as_secs_f64()), "{t:?}");
    }

    #[test]
    fn times_print_as_six_decimals_of_seconds() {
        let us = |s: u64, u: u32| Duration::new(s, u * 1000);
        for t in [
            Duration::ZERO,
            us(0, 1),
            us(0, 999_999),
            us(1, 0),
            us(9, 999_999),
            us(1_795_664_797, 622_242),
            us(1_436_509_052, 249_713),
            us(EXACT_SECS - 1, 999_999),
            us(EXACT_SECS - 1, 500_000),
            us(EXACT_SECS, 0),
            us(EXACT_SECS, 999_999),
            us(1 << 40, 123_457),
            us(u64::MAX, 999_999),
            Duration::new(1, 1),
            Duration::new(1, 999_999_999),
            Duration::new(1_795_664_797, 622_242_500),
            Duration::new(0, 500),
        ] {
            check_time(t);
        }
        let mut rng = Rng(7);
        for _ in 0..300_000 {
            let secs = rng.next() % EXACT_SECS;
            let micros = (rng.next() % 1_000_000) as u32;
            check_time(us(secs, micros));
            check_time(us(secs >> (rng.next() % 32), micros));
            check_time(Duration::new(
                rng.next() % (EXACT_SECS * 4),
                (rng.next() % 1_000_000_000) as u32,
            ));
        }
    }

    #[test]
    fn hex_ids_print_as_three_upper_case_digits_at_least() {
        let mut out = Vec::new();
        for id in [
            0,
            1,
            0xF,
            0x10,
            0xFF,
            0x100,
            0x7FF,
            0xFFF,
            0x1000,
            0x1FFF_FFFF,
            u32::MAX,
        ] {
            out.clear();
            push_hex_id(&mut out, id);
            assert_eq!(String::from_utf8_lossy(&out), format!("0x{id:03X}"));
        }
    }
}

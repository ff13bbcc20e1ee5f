//! SecurityAccess level 1 (ISO 14229-1 clause 10.4): the seed/key exchange, the attempt
//! counter and the delay after the third wrong key (NRC 0x36, then 0x37 until it expires).
//! The key is `rotate_left(seed XOR 0x4444_5443, 7)` ("DDTC"), big-endian on the bus.

use std::time::Duration;

use super::nrc::Nrc;

/// The constant XORed into the seed ("DDTC").
pub(crate) const KEY_CONSTANT: u32 = 0x4444_5443;
/// Wrong keys in a row that lock the level.
pub(crate) const MAX_ATTEMPTS: u8 = 3;
/// How long the level stays locked after [`MAX_ATTEMPTS`] wrong keys.
pub(crate) const DELAY: Duration = Duration::from_secs(10);

/// The key of a seed.
pub fn key(seed: u32) -> u32 {
    (seed ^ KEY_CONSTANT).rotate_left(7)
}

/// The state of security level 1.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Security {
    unlocked: bool,
    /// The seed sent and not yet answered.
    seed: Option<u32>,
    /// Wrong keys in a row.
    failed: u8,
    /// End of the delay after the third wrong key.
    delay_until: Option<Duration>,
}

impl Security {
    /// Whether the level is unlocked.
    pub fn is_unlocked(&self) -> bool {
        self.unlocked
    }

    /// Locks the level again (a session change, the S3 timeout); the attempt counter and a
    /// running delay are kept.
    pub fn lock(&mut self) {
        self.unlocked = false;
        self.seed = None;
    }

    /// `27 01`: the seed to send (all zero when already unlocked). `draw` gives a new seed.
    pub fn request_seed(
        &mut self,
        now: Duration,
        draw: impl FnOnce() -> u32,
    ) -> Result<[u8; 4], Nrc> {
        self.handle_timeout(now);
        if self.delay_until.is_some() {
            return Err(Nrc::RequiredTimeDelayNotExpired);
        }
        if self.unlocked {
            return Ok([0; 4]);
        }
        // A zero seed means "unlocked" on the bus: never send it for a locked level.
        let seed = draw().max(1);
        self.seed = Some(seed);
        Ok(seed.to_be_bytes())
    }

    /// `27 02 key`: unlocks on the right key; a wrong one counts (0x35, the third 0x36 and
    /// the delay). Either way the seed is used up.
    pub fn send_key(&mut self, now: Duration, key_sent: u32) -> Result<(), Nrc> {
        let seed = self.seed.take().ok_or(Nrc::RequestSequenceError)?;
        if key_sent == key(seed) {
            self.unlocked = true;
            self.failed = 0;
            return Ok(());
        }
        self.failed = self.failed.saturating_add(1);
        if self.failed >= MAX_ATTEMPTS {
            self.failed = 0;
            self.delay_until = Some(now + DELAY);
            return Err(Nrc::ExceededNumberOfAttempts);
        }
        Err(Nrc::InvalidKey)
    }

    /// When the delay ends, if it runs.
    pub fn deadline(&self) -> Option<Duration> {
        self.delay_until
    }

    /// Ends the delay once it has expired.
    pub fn handle_timeout(&mut self, now: Duration) {
        if self.delay_until.is_some_and(|t| now >= t) {
            self.delay_until = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_of_a_fixed_seed_by_hand() {
        // 0x12345678 ^ 0x44445443 = 0x5670023B; rotated left by 7:
        // (0x5670023B << 7) mod 2^32 = 0x38011D80, 0x5670023B >> 25 = 0x2B.
        assert_eq!(key(0x1234_5678), 0x3801_1DAB);
        // 0 ^ 0x44445443 = 0x44445443; << 7 = 0x222A2180, >> 25 = 0x22.
        assert_eq!(key(0), 0x222A_21A2);
    }
}

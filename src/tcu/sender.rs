//! A second sender on an input id (issue 12: spoofing). E2E (DESIGN.md §3) catches a corrupted
//! or frozen sender, not a second node that sends the same message with a valid CRC: if it keeps
//! its own counter, the frames of the two arrive interleaved, twice as often as the message's
//! cycle, and their counters break the sequence (repeats and jumps) — and a node that follows the
//! real counter makes the real sender's frames repeat its counters. Either way the id shows
//! **more CRC-valid frames than its cycle allows together with counter errors**.
//!
//! Rule: within the last [`WINDOW_CYCLES`] cycles of the message, at least
//! [`MIN_FRAMES_PER_WINDOW`] CRC-valid frames (1.5 per cycle; one sender gives one, and a
//! scheduling burst of a late sender does not raise the average over the window) of which at
//! least [`MIN_COUNTER_ERRORS`] broke the counter sequence. The condition ends when the window no
//! longer holds it. Pure: times are arguments.
//!
//! A flood of corrupted frames on the id (issue 12: a bad-CRC flood at thousands of frames/s
//! beside the real sender) is the same excess with CRC errors instead of counter errors: within
//! the window at least [`MIN_FRAMES_PER_WINDOW`] frames in all of which at least
//! [`MIN_COUNTER_ERRORS`] failed the CRC ([`SenderMonitor::flooded`]). The real sender's valid
//! frames keep the input fresh, so without this the TCU drove on under the flood.

use std::collections::VecDeque;
use std::time::Duration;

/// Cycles of the sliding window.
pub const WINDOW_CYCLES: u32 = 10;
/// CRC-valid frames in the window that a single sender cannot produce.
pub const MIN_FRAMES_PER_WINDOW: usize = 15;
/// Counter errors in the window that a double rate must come with.
pub const MIN_COUNTER_ERRORS: usize = 3;

/// How a frame of the id passed the end-to-end check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// CRC valid, counter in sequence.
    Valid,
    /// CRC valid, counter repeated or jumped.
    CounterError,
    /// Failed the CRC.
    BadCrc,
}

/// The frames of one id over the last window, each with how it passed the E2E check.
#[derive(Debug, Clone, Default)]
pub(crate) struct SenderMonitor {
    frames: VecDeque<(Duration, Kind)>,
}

impl SenderMonitor {
    /// A CRC-valid frame arrived at `at`; `counter_error`: it repeated or jumped the counter.
    /// `cycle` is the message's cycle time. Returns whether a second sender is evident.
    pub fn frame(&mut self, at: Duration, counter_error: bool, cycle: Duration) -> bool {
        let kind = if counter_error {
            Kind::CounterError
        } else {
            Kind::Valid
        };
        self.push(at, kind, cycle);
        self.evident(at, cycle)
    }

    /// A frame that failed the CRC arrived at `at`. Returns whether the id is flooded.
    pub fn bad_crc(&mut self, at: Duration, cycle: Duration) -> bool {
        self.push(at, Kind::BadCrc, cycle);
        self.flooded(at, cycle)
    }

    fn push(&mut self, at: Duration, kind: Kind, cycle: Duration) {
        let window = cycle * WINDOW_CYCLES;
        while self
            .frames
            .front()
            .is_some_and(|(t, _)| at.saturating_sub(*t) >= window)
        {
            self.frames.pop_front();
        }
        self.frames.push_back((at, kind));
    }

    /// Whether the id is flooded with corrupted frames at `now`: more frames than a sender's
    /// cycle allows in the window, of which at least [`MIN_COUNTER_ERRORS`] failed the CRC.
    pub fn flooded(&self, now: Duration, cycle: Duration) -> bool {
        self.window(now, cycle).flooded()
    }

    /// Whether a second sender is evident at `now`: more CRC-valid frames than one sender's
    /// cycle allows, of which at least [`MIN_COUNTER_ERRORS`] broke the counter sequence.
    pub fn evident(&self, now: Duration, cycle: Duration) -> bool {
        self.window(now, cycle).evident()
    }

    /// The frames in the window at `now` by how they passed, in one pass (both conditions of a
    /// cycle's health check read it).
    pub fn window(&self, now: Duration, cycle: Duration) -> Window {
        let window = cycle * WINDOW_CYCLES;
        let mut w = Window::default();
        for (t, k) in &self.frames {
            if now.saturating_sub(*t) < window {
                match k {
                    Kind::Valid => w.valid += 1,
                    Kind::CounterError => w.counter_errors += 1,
                    Kind::BadCrc => w.bad_crc += 1,
                }
            }
        }
        w
    }
}

/// The frames of an id within the window, by how they passed the E2E check.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Window {
    valid: usize,
    counter_errors: usize,
    bad_crc: usize,
}

impl Window {
    /// A flood of corrupted frames: at least [`MIN_FRAMES_PER_WINDOW`] frames in all, of which at
    /// least [`MIN_COUNTER_ERRORS`] failed the CRC.
    pub fn flooded(&self) -> bool {
        let n = self.valid + self.counter_errors + self.bad_crc;
        self.bad_crc >= MIN_COUNTER_ERRORS && n >= MIN_FRAMES_PER_WINDOW
    }

    /// A second sender: at least [`MIN_FRAMES_PER_WINDOW`] CRC-valid frames, of which at least
    /// [`MIN_COUNTER_ERRORS`] broke the counter sequence.
    pub fn evident(&self) -> bool {
        let n = self.valid + self.counter_errors;
        n >= MIN_FRAMES_PER_WINDOW && self.counter_errors >= MIN_COUNTER_ERRORS
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CYCLE: Duration = Duration::from_millis(crate::can::messages::DrvPedal::CYCLE_MS as u64);

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    /// One sender on its cycle, with jitter and a burst after a stall: never a second sender,
    /// even with the odd counter error (a frame lost on the bus).
    #[test]
    fn one_sender_is_never_two() {
        let mut m = SenderMonitor::default();
        let mut t = 0;
        for k in 0..500u64 {
            // 40 ms stall every 100 frames, then the four frames at once.
            t += if k % 100 < 4 && k > 4 { 0 } else { 10 };
            let err = k % 37 == 0;
            assert!(!m.frame(ms(t), err, CYCLE), "frame {k} at {t} ms");
        }
    }

    /// A second node with its own counter, in step with the real one: evident within a window,
    /// and over once it stops.
    #[test]
    fn two_interleaved_senders_are_found_and_forgotten() {
        let mut m = SenderMonitor::default();
        let mut found_at = None;
        for k in 0..30u64 {
            let t = k * 10;
            m.frame(ms(t), false, CYCLE);
            // The spoofer, 3 ms later: its counter jumps against the real one's every time.
            if m.frame(ms(t + 3), true, CYCLE) && found_at.is_none() {
                found_at = Some(t + 3);
            }
        }
        let at = found_at.expect("not found");
        assert!(at <= 100, "found at {at} ms");
        // The spoofer stops: the real sender alone clears the condition within a window.
        let mut cleared = None;
        for k in 30..60u64 {
            if !m.frame(ms(k * 10), false, CYCLE) && cleared.is_none() {
                cleared = Some(k * 10);
            }
        }
        assert!(cleared.is_some_and(|c| c <= 300 + 100), "{cleared:?}");
    }

    /// A bad-CRC flood beside the real sender (2 frames/ms): flooded within 8 ms, not a second
    /// sender, and over a window after it stops; one sender whose every frame fails the CRC (a
    /// corrupted sender, the timeout path's case) is no flood.
    #[test]
    fn a_bad_crc_flood_is_found_and_forgotten() {
        let mut m = SenderMonitor::default();
        for k in 0..20u64 {
            assert!(
                !m.bad_crc(ms(k * 10), CYCLE),
                "one corrupted sender at {} ms",
                k * 10
            );
        }
        let mut m = SenderMonitor::default();
        let mut found = None;
        for t in 0..300u64 {
            if t % 10 == 0 {
                m.frame(ms(t), false, CYCLE);
            }
            if (100..200).contains(&t) {
                let f1 = m.bad_crc(ms(t), CYCLE);
                let f2 = m.bad_crc(ms(t), CYCLE);
                if (f1 || f2) && found.is_none() {
                    found = Some(t);
                }
            }
            assert!(!m.evident(ms(t), CYCLE), "no second sender at {t} ms");
        }
        assert!(found.is_some_and(|t| t <= 108), "{found:?}");
        assert!(m.flooded(ms(295), CYCLE));
        assert!(!m.flooded(ms(300), CYCLE), "over a window after the flood");
    }
}

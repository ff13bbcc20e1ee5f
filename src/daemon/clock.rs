//! The daemons' one time base: monotonic time since the start (`CLOCK_MONOTONIC` through tokio's
//! `Instant`), onto which the bus's receive timestamps are mapped, with the time during which the
//! daemon itself could not run taken out.
//!
//! - **Monotonic.** A kernel receive timestamp is wall-clock time (`SO_TIMESTAMPNS`), which a
//!   clock step moves. Only its *age* at reading (wall now − timestamp) is used, and the arrival
//!   on the monotonic base is `now − age`, clamped to `[floor, now]`, where `floor` is the last
//!   time the daemon found its receive queue empty: every frame still queued arrived after that.
//!   A clock step of any size can so misplace a frame only within the time since the queue was
//!   last empty (normally under a cycle), and never makes time run backwards.
//! - **Live time.** A timeout must tell a dead sender from a late reader. When the daemon wakes
//!   up later than its own timer's deadline by more than [`STALL_TOLERANCE`], it was not running
//!   (the host descheduled it, or the whole User-Mode Linux guest with every sender in it); that
//!   interval is a *stall* and is not counted against any sender. The time base the cores see is
//!   the monotonic time minus all stall time so far ("live" time): a frame that arrived during a
//!   stall is placed at the stall's start, and a message is missing only after `timeout_cycles`
//!   of its cycles of live time. A sender that really stops is still detected, later by at most
//!   the length of the reader's own stalls in between. The stalls are counted and reported.
//! - **Bus time** ([`BusClock`], a lockstep bench): the plant's simulated time, counted in its
//!   sync frames (one DCT_Sensors frame per 10 ms cycle). The plant waits for the controller's
//!   (and a scripted driver's) answer before simulating the next cycle, so time stands still while
//!   any of them is descheduled: every timeout, detection and recovery is then exact in cycles,
//!   whatever the host does. A sync frame carries the next cycle's time; any other frame belongs
//!   to the cycle coming (the plant's inputs before its sync, the answers to the last one).
//!
//! Pure: the current instants are arguments.

use std::time::Duration;

/// A wake-up later than the pending timer deadline by more than this is a stall of the daemon.
pub const STALL_TOLERANCE: Duration = Duration::from_millis(5);

/// The monotonic, stall-free time base of a daemon (times relative to its start).
#[derive(Debug, Clone, Default)]
pub struct TimeBase {
    /// Monotonic time at which the receive queue was last found empty.
    floor: Duration,
    /// Total stall time so far.
    credit: Duration,
    /// The last stall: its start and end on the monotonic base, and the credit before it.
    last_stall: Option<(Duration, Duration, Duration)>,
    stalls: u64,
    longest: Duration,
}

impl TimeBase {
    pub fn new() -> Self {
        Self::default()
    }

    /// Monotonic arrival time of a frame with wall-clock receive timestamp `stamp`, read at
    /// monotonic time `mono_now` when the wall clock read `wall_now`.
    pub fn arrival(&self, stamp: Duration, wall_now: Duration, mono_now: Duration) -> Duration {
        let age = wall_now.saturating_sub(stamp);
        mono_now
            .saturating_sub(age)
            .clamp(self.floor.min(mono_now), mono_now)
    }

    /// The receive queue was found empty at `mono_now`.
    pub fn queue_empty(&mut self, mono_now: Duration) {
        self.floor = self.floor.max(mono_now);
    }

    /// The daemon woke up at `mono_now` with its timer's next deadline at `deadline`: a stall when
    /// it is more than [`STALL_TOLERANCE`] late. Returns the stall's length when there was one.
    pub fn woke(&mut self, mono_now: Duration, deadline: Duration) -> Option<Duration> {
        let late = mono_now.checked_sub(deadline)?;
        if late <= STALL_TOLERANCE {
            return None;
        }
        // A stall overlapping the previous one only adds its new part.
        let from = match self.last_stall {
            Some((_, end, _)) => deadline.max(end),
            None => deadline,
        };
        let added = mono_now.checked_sub(from).filter(|d| !d.is_zero())?;
        match self.last_stall {
            Some((start, end, before)) if from == end => {
                self.last_stall = Some((start, mono_now, before));
            }
            _ => {
                self.last_stall = Some((from, mono_now, self.credit));
                self.stalls += 1;
            }
        }
        self.credit += added;
        self.longest = self.longest.max(late);
        Some(added)
    }

    /// The monotonic time at which live time reaches `live`, for a `live` after the last stall
    /// (a deadline of the core): the inverse of [`TimeBase::live`] there.
    pub fn mono_of(&self, live: Duration) -> Duration {
        live + self.credit
    }

    /// Live time (stall time taken out) of monotonic time `mono`. Monotone non-decreasing.
    pub fn live(&self, mono: Duration) -> Duration {
        match self.last_stall {
            Some((_, end, _)) if mono >= end => mono - self.credit,
            // Inside the last stall: its start; before it: the credit of the time before.
            Some((start, _, before)) => mono.min(start).saturating_sub(before),
            None => mono,
        }
    }

    /// Stalls so far, their total and the longest one.
    pub fn stalls(&self) -> (u64, Duration, Duration) {
        (self.stalls, self.credit, self.longest)
    }
}

/// Bus time of a lockstep bench: cycles of the plant's sync frames (see the module doc).
#[derive(Debug, Clone)]
pub struct BusClock {
    cycle: Duration,
    /// The time the next sync frame carries.
    next: Duration,
}

impl BusClock {
    pub fn new(cycle: Duration) -> Self {
        Self {
            cycle,
            next: Duration::ZERO,
        }
    }

    /// A sync frame arrived: its cycle's time.
    pub fn sync(&mut self) -> Duration {
        let t = self.next;
        self.next += self.cycle;
        t
    }

    /// Any other frame: it belongs to the coming cycle.
    pub fn stamp(&self) -> Duration {
        self.next
    }

    /// A computation without a sync frame (the plant silent for long): time moves on a cycle,
    /// so a dead plant is still detected as missing sensors.
    pub fn idle(&mut self) -> Duration {
        self.sync()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bus_time_counts_cycles_of_sync_frames_whatever_the_wall_clock() {
        let mut bc = BusClock::new(ms(10));
        // Cycle 0: the plant's inputs, its sync, then the frames that follow it.
        assert_eq!(bc.stamp(), ms(0), "ENG_Status before the first sync");
        assert_eq!(bc.sync(), ms(0));
        assert_eq!(
            bc.stamp(),
            ms(10),
            "DCT_Actuators after it: the next computation's"
        );
        assert_eq!(bc.sync(), ms(10));
        // The plant silent: two idle computations move time on.
        assert_eq!(bc.idle(), ms(20));
        assert_eq!(bc.idle(), ms(30));
        assert_eq!(bc.sync(), ms(40));
        assert_eq!(bc.stamp(), ms(50));
    }

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    #[test]
    fn arrival_is_now_minus_age_within_the_queue_window() {
        let mut tb = TimeBase::new();
        tb.queue_empty(ms(1000));
        // Received 3 ms before reading.
        assert_eq!(tb.arrival(ms(50_000), ms(50_003), ms(1005)), ms(1002));
    }

    #[test]
    fn clock_steps_of_three_seconds_either_way_move_nothing_outside_the_queue_window() {
        let mut tb = TimeBase::new();
        tb.queue_empty(ms(1000));
        // Wall clock stepped forward 3 s between the frame's receipt and its reading: the age
        // looks like 3 s, but the frame cannot be older than the last empty queue.
        assert_eq!(tb.arrival(ms(50_000), ms(53_002), ms(1002)), ms(1000));
        // Stepped back 3 s: the stamp lies in the future; the frame is taken as just arrived.
        assert_eq!(tb.arrival(ms(50_000), ms(47_001), ms(1002)), ms(1002));
        // Never before the queue window, never after now, time never runs backwards.
        for wall_now in [0, 1, 40_000, 50_000, 60_000, 1 << 40] {
            let a = tb.arrival(ms(50_000), ms(wall_now), ms(1002));
            assert!((ms(1000)..=ms(1002)).contains(&a), "{wall_now}: {a:?}");
        }
    }

    #[test]
    fn a_stall_is_taken_out_of_live_time_and_frames_within_it_sit_at_its_start() {
        let mut tb = TimeBase::new();
        assert_eq!(tb.woke(ms(13), ms(10)), None, "3 ms late is no stall");
        assert_eq!(tb.live(ms(13)), ms(13));
        // Woke at 75 ms for the 20 ms deadline: a 55 ms stall.
        assert_eq!(tb.woke(ms(75), ms(20)), Some(ms(55)));
        assert_eq!(tb.live(ms(19)), ms(19));
        assert_eq!(tb.live(ms(20)), ms(20));
        assert_eq!(tb.live(ms(50)), ms(20), "a frame received during the stall");
        assert_eq!(tb.live(ms(75)), ms(20));
        assert_eq!(tb.live(ms(85)), ms(30));
        // A second stall adds up.
        assert_eq!(tb.woke(ms(120), ms(90)), Some(ms(30)));
        assert_eq!(tb.live(ms(130)), ms(45));
        assert_eq!(tb.stalls(), (2, ms(85), ms(55)));
        // Live time is monotone.
        let mut prev = Duration::ZERO;
        for t in 0..200 {
            let l = tb.live(ms(t));
            assert!(l >= prev, "{t}");
            prev = l;
        }
    }

    #[test]
    fn a_sender_silent_for_three_live_cycles_is_still_missing() {
        // The reader stalls 100 ms right after the sender's last frame at 10 ms; the sender is
        // dead. Its age in live time passes 30 ms 30 ms after the stall, not before.
        let mut tb = TimeBase::new();
        tb.woke(ms(120), ms(20));
        let last = tb.live(ms(10));
        assert!(tb.live(ms(139)) - last < ms(30));
        assert!(tb.live(ms(141)) - last >= ms(30));
    }

    #[test]
    fn overlapping_wakeups_of_one_stall_count_it_once() {
        let mut tb = TimeBase::new();
        assert_eq!(tb.woke(ms(60), ms(10)), Some(ms(50)));
        // The same deadline seen again at 70 ms (another wake-up in the stall's aftermath).
        assert_eq!(tb.woke(ms(70), ms(10)), Some(ms(10)));
        assert_eq!(tb.stalls(), (1, ms(60), ms(60)));
        assert_eq!(tb.live(ms(80)), ms(20));
    }
}

//! The bench's recorder: every frame on the bus with its receive timestamp (the kernel's on
//! SocketCAN), on its own thread, runtime and node. It says when its node listens
//! ([`Recorder::spawn`] returns after that) and publishes what it has seen so far ([`Seen`]), so
//! the harness ends a run when the recording is complete instead of sleeping and hoping.

use super::net::Net;
use crate::can::messages::{ids, message_def};
use crate::can::{Bus, BusError, CanFrame};
use std::thread::JoinHandle;
use std::time::Duration;
use tokio::sync::watch;

/// What the recorder has seen so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Seen {
    /// Frames recorded.
    pub frames: u64,
    /// Frames of a message the TCU does not send (the DBC's sender): the plant's, the driver's,
    /// a pinger's.
    pub not_tcu: u64,
    /// Index (1-based, in `frames`) of the last DCT_Sensors frame, 0 before the first.
    pub last_sensors: u64,
    /// Index of the last TCU_ClutchCmd: the TCU's answer to a DCT_Sensors frame (its other
    /// messages, TCU_Status say, may go out on their own between a sensor frame and its answer).
    pub last_answer: u64,
}

impl Seen {
    /// Counts one frame.
    pub fn record(&mut self, frame: &CanFrame) {
        self.frames += 1;
        let id = frame.standard_id();
        let by_tcu = id
            .and_then(|id| message_def(u32::from(id)))
            .is_some_and(|m| m.sender == "TCU");
        if !by_tcu {
            self.not_tcu += 1;
        }
        if id == Some(ids::DCT_SENSORS) {
            self.last_sensors = self.frames;
        }
        if id == Some(ids::TCU_CLUTCH_CMD) {
            self.last_answer = self.frames;
        }
    }

    /// True when at least `sent` frames of the other nodes were recorded and the TCU answered
    /// the last DCT_Sensors frame (a TCU_ClutchCmd after it).
    pub fn complete(&self, sent: u64) -> bool {
        self.not_tcu >= sent && self.last_answer > self.last_sensors
    }
}

/// Errors of the recorder's thread.
#[derive(Debug, thiserror::Error)]
pub enum RecorderError {
    #[error("recorder: starting its runtime")]
    Runtime(#[source] std::io::Error),
    #[error("recorder")]
    Bus(#[from] BusError),
    #[error("the recorder's thread panicked")]
    Panicked,
    #[error("the recorder's node did not come up within {0:?}")]
    NotReady(Duration),
}

/// A running recorder.
pub struct Recorder {
    thread: JoinHandle<Result<Vec<(Duration, CanFrame)>, RecorderError>>,
    stop: watch::Sender<bool>,
    seen: watch::Receiver<Seen>,
}

/// How long a node may take to open its socket.
pub(crate) const READY_TIMEOUT: Duration = Duration::from_secs(5);

impl Recorder {
    /// Starts recording on `net`; returns once the recorder's node listens. `before` runs first
    /// on the recorder's thread (e.g. the real-time priority).
    pub fn spawn(net: Net, before: impl FnOnce() + Send + 'static) -> Result<Self, RecorderError> {
        let (stop, stop_rx) = watch::channel(false);
        let (seen_tx, seen) = watch::channel(Seen::default());
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let thread = std::thread::spawn(move || {
            before();
            let rt = crate::daemon::runtime().map_err(RecorderError::Runtime)?;
            rt.block_on(record(net, stop_rx, seen_tx, ready_tx))
        });
        match ready_rx.recv_timeout(READY_TIMEOUT) {
            Ok(()) => Ok(Recorder { thread, stop, seen }),
            // The thread ended without its node (its error says why) or hangs.
            Err(_) if thread.is_finished() => {
                Err(join(thread).err().unwrap_or(RecorderError::Panicked))
            }
            Err(_) => Err(RecorderError::NotReady(READY_TIMEOUT)),
        }
    }

    /// What it has seen so far.
    pub fn seen(&self) -> Seen {
        *self.seen.borrow()
    }

    /// Waits until [`Seen::complete`] for `sent` frames of the other nodes, at most `timeout`;
    /// returns whether it was.
    pub async fn settle(&mut self, sent: u64, timeout: Duration) -> bool {
        let wait = self.seen.wait_for(|s| s.complete(sent));
        matches!(tokio::time::timeout(timeout, wait).await, Ok(Ok(_)))
    }

    /// Stops and returns the recording (the frames already queued included).
    pub fn finish(self) -> Result<Vec<(Duration, CanFrame)>, RecorderError> {
        let _ = self.stop.send(true);
        join(self.thread)
    }
}

fn join<T>(t: JoinHandle<Result<T, RecorderError>>) -> Result<T, RecorderError> {
    t.join().map_err(|_| RecorderError::Panicked)?
}

async fn record(
    net: Net,
    mut stop: watch::Receiver<bool>,
    seen_tx: watch::Sender<Seen>,
    ready: std::sync::mpsc::Sender<()>,
) -> Result<Vec<(Duration, CanFrame)>, RecorderError> {
    let mut bus = net.open()?;
    let _ = ready.send(());
    let mut frames = Vec::with_capacity(1 << 16);
    let mut seen = Seen::default();
    let keep = |frames: &mut Vec<_>, t: Duration, f: CanFrame, seen: &mut Seen| {
        seen.record(&f);
        frames.push((t, f));
    };
    loop {
        tokio::select! {
            biased;
            rx = bus.recv() => match rx {
                Ok(r) => {
                    keep(&mut frames, r.timestamp, r.frame, &mut seen);
                    seen_tx.send_replace(seen);
                }
                Err(e) if e.is_frame_level() => {}
                Err(e) => return Err(e.into()),
            },
            _ = stop.wait_for(|s| *s) => break,
        }
    }
    // Frames already queued.
    while let Ok(Some(r)) = bus.try_recv() {
        keep(&mut frames, r.timestamp, r.frame, &mut seen);
    }
    Ok(frames)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::Bus;

    fn frame(id: u16) -> CanFrame {
        CanFrame::standard(id, &[0; 8]).unwrap()
    }

    #[test]
    fn a_recording_is_complete_once_the_tcu_answered_the_last_sensor_frame() {
        let mut s = Seen::default();
        s.record(&frame(ids::ENG_STATUS));
        s.record(&frame(ids::DCT_SENSORS));
        assert!(!s.complete(2), "no answer yet: {s:?}");
        s.record(&frame(ids::TCU_CLUTCH_CMD));
        assert!(s.complete(2), "{s:?}");
        assert!(!s.complete(3), "a frame of the plant still missing: {s:?}");
        s.record(&frame(ids::DCT_SENSORS));
        assert!(
            !s.complete(3),
            "the new sensor frame is not answered: {s:?}"
        );
        // Another message of the TCU is not the answer (under load the TCU's status can go
        // out between a sensor frame and its answer; the recording must not end there).
        s.record(&frame(ids::TCU_ENGINE_REQ));
        s.record(&frame(ids::TCU_STATUS));
        assert!(!s.complete(3), "{s:?}");
        s.record(&frame(ids::TCU_CLUTCH_CMD));
        assert_eq!((s.frames, s.not_tcu), (7, 3));
        assert!(s.complete(3), "{s:?}");
    }

    /// `settle` waits for an answer that comes late (40 ms after the sensor frame, later than
    /// any scheduling delay here), and gives up after its timeout when none comes.
    #[test]
    fn settle_waits_for_a_late_answer_and_gives_up_without_one() {
        let bus = crate::can::InProcessBus::new("settle-test");
        let net = Net::Sim(bus.clone());
        let mut rec = Recorder::spawn(net.clone(), || {}).unwrap();
        let rt = crate::daemon::runtime().unwrap();
        let (answered, waited) = rt.block_on(async {
            let mut node = net.open().unwrap();
            node.send(frame(ids::DCT_SENSORS)).await.unwrap();
            let t0 = std::time::Instant::now();
            let late = tokio::spawn(async move {
                tokio::time::sleep(Duration::from_millis(40)).await;
                node.send(frame(ids::TCU_CLUTCH_CMD)).await.unwrap();
                node
            });
            let answered = rec.settle(1, Duration::from_secs(2)).await;
            let waited = t0.elapsed();
            let mut node = late.await.unwrap();
            // A new sensor frame nobody answers: settle gives up after its timeout.
            node.send(frame(ids::DCT_SENSORS)).await.unwrap();
            let t1 = std::time::Instant::now();
            let unanswered = rec.settle(2, Duration::from_millis(100)).await;
            assert!(!unanswered);
            assert!(t1.elapsed() >= Duration::from_millis(100));
            (answered, waited)
        });
        assert!(answered);
        assert!(waited >= Duration::from_millis(40), "{waited:?}");
        let frames = rec.finish().unwrap();
        let ids: Vec<_> = frames
            .iter()
            .map(|(_, f)| f.standard_id().unwrap())
            .collect();
        assert_eq!(
            ids,
            [ids::DCT_SENSORS, ids::TCU_CLUTCH_CMD, ids::DCT_SENSORS]
        );
    }
}

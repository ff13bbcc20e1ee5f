//! The `Bus` trait the daemons talk through, and the in-process bus.
//!
//! A bus sends frames and receives them with a receive timestamp. Two implementations: SocketCAN
//! (`super::socketcan`, kernel timestamps) and [`InProcessBus`], where any number of endpoints see
//! each other's frames the way nodes on a real bus do (every other endpoint receives every frame,
//! in send order; the sender receives its own frames only when own-echo is on). The in-process
//! bus stamps frames with a [`Clock`], real or simulated, so tests run in simulated time.

use super::frame::CanFrame;
use std::collections::VecDeque;
use std::future::Future;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};
use thiserror::Error;
use tokio::sync::Notify;

/// A received frame and when it arrived (time since the Unix epoch for real buses, or the
/// simulated clock's time).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Received {
    pub frame: CanFrame,
    pub timestamp: Duration,
}

/// Bus failures.
#[derive(Debug, Error)]
pub enum BusError {
    #[error("CAN interface {iface}: {source}")]
    Io {
        iface: String,
        #[source]
        source: std::io::Error,
    },
    #[error("CAN interface {iface}: error frame {id:#x} received")]
    ErrorFrame { iface: String, id: u32 },
    #[error("CAN interface {iface}: unsupported frame ({what})")]
    Unsupported { iface: String, what: String },
    #[error("CAN interface {iface}: a received frame cannot be represented")]
    BadFrame {
        iface: String,
        #[source]
        source: crate::can::frame::FrameError,
    },
    #[error("bus {iface} is closed")]
    Closed { iface: String },
    /// A SocketCAN endpoint was opened outside the tokio runtime that must own its socket (a
    /// programming error of the caller, reported instead of the runtime's panic).
    #[error(
        "CAN interface {iface}: opened outside a tokio runtime (open it on the runtime that \
         will use it, or use SocketCanBus::probe for a check without one)"
    )]
    NoRuntime { iface: String },
}

impl BusError {
    /// True for an error of one frame (an error frame, a frame the bus cannot carry or
    /// represent): the bus itself goes on.
    pub fn is_frame_level(&self) -> bool {
        matches!(
            self,
            BusError::ErrorFrame { .. } | BusError::Unsupported { .. } | BusError::BadFrame { .. }
        )
    }
}

/// A CAN bus endpoint.
pub trait Bus: Send {
    /// Sends one frame.
    fn send(&mut self, frame: CanFrame) -> impl Future<Output = Result<(), BusError>> + Send;
    /// Waits for the next frame. Cancel-safe: a dropped future loses no frame.
    fn recv(&mut self) -> impl Future<Output = Result<Received, BusError>> + Send;
    /// The next frame if one is waiting.
    fn try_recv(&mut self) -> Result<Option<Received>, BusError>;
    /// Up to `max` frames that are already waiting, appended to `out` in arrival order (a read
    /// that fails is an `Err` in its place, and ends the batch); returns whether the receive
    /// queue was found empty. One system call per batch where the bus can (SocketCAN's
    /// `recvmmsg`); by default [`Bus::try_recv`] in a loop.
    fn try_recv_many(&mut self, max: usize, out: &mut Vec<Result<Received, BusError>>) -> bool {
        for _ in 0..max {
            match self.try_recv() {
                Ok(Some(rx)) => out.push(Ok(rx)),
                Ok(None) => return true,
                Err(e) => {
                    out.push(Err(e));
                    return false;
                }
            }
        }
        false
    }
    /// Interface name for messages and logs.
    fn iface(&self) -> &str;
}

/// A source of time for receive timestamps.
pub trait Clock: Send + Sync {
    fn now(&self) -> Duration;
}

/// Wall-clock time since the Unix epoch.
#[derive(Debug, Clone, Copy, Default)]
pub struct SystemClock;

impl Clock for SystemClock {
    fn now(&self) -> Duration {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default()
    }
}

/// A simulated clock, advanced by whoever owns the simulation.
#[derive(Debug, Default)]
pub struct ManualClock {
    nanos: AtomicU64,
}

impl ManualClock {
    pub fn new(start: Duration) -> Self {
        Self {
            nanos: AtomicU64::new(start.as_nanos() as u64),
        }
    }
    pub fn set(&self, t: Duration) {
        self.nanos.store(t.as_nanos() as u64, Ordering::SeqCst);
    }
    pub fn advance(&self, dt: Duration) {
        self.nanos.fetch_add(dt.as_nanos() as u64, Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn now(&self) -> Duration {
        Duration::from_nanos(self.nanos.load(Ordering::SeqCst))
    }
}

impl<C: Clock + ?Sized> Clock for Arc<C> {
    fn now(&self) -> Duration {
        (**self).now()
    }
}

/// Per-endpoint options.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EndpointConfig {
    /// Receive own frames too (like `CAN_RAW_RECV_OWN_MSGS`).
    pub own_echo: bool,
    /// Receive queue length; older frames are dropped (and counted) when it overflows, as a
    /// socket's receive buffer does.
    pub queue: usize,
}

impl Default for EndpointConfig {
    fn default() -> Self {
        Self {
            own_echo: false,
            queue: 4096,
        }
    }
}

struct Inbox {
    id: u64,
    own_echo: bool,
    capacity: usize,
    queue: Mutex<VecDeque<Received>>,
    dropped: AtomicU64,
    notify: Notify,
}

struct Shared {
    name: String,
    clock: Arc<dyn Clock>,
    inboxes: Mutex<Vec<Arc<Inbox>>>,
    next_id: AtomicU64,
}

/// An in-process CAN bus; clone it freely, create endpoints with [`InProcessBus::endpoint`].
#[derive(Clone)]
pub struct InProcessBus {
    shared: Arc<Shared>,
}

impl std::fmt::Debug for InProcessBus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("InProcessBus")
            .field("name", &self.shared.name)
            .finish()
    }
}

impl InProcessBus {
    /// A bus stamped with wall-clock time.
    pub fn new(name: &str) -> Self {
        Self::with_clock(name, Arc::new(SystemClock))
    }

    /// A bus stamped with the given clock (e.g. a [`ManualClock`] for simulated time).
    pub fn with_clock(name: &str, clock: Arc<dyn Clock>) -> Self {
        Self {
            shared: Arc::new(Shared {
                name: name.to_string(),
                clock,
                inboxes: Mutex::new(Vec::new()),
                next_id: AtomicU64::new(0),
            }),
        }
    }

    /// A new node on this bus.
    pub fn endpoint(&self, config: EndpointConfig) -> InProcessEndpoint {
        let inbox = Arc::new(Inbox {
            id: self.shared.next_id.fetch_add(1, Ordering::SeqCst),
            own_echo: config.own_echo,
            capacity: config.queue.max(1),
            queue: Mutex::new(VecDeque::new()),
            dropped: AtomicU64::new(0),
            notify: Notify::new(),
        });
        lock(&self.shared.inboxes).push(inbox.clone());
        InProcessEndpoint {
            shared: self.shared.clone(),
            inbox,
        }
    }

    /// The bus clock's time.
    pub fn now(&self) -> Duration {
        self.shared.clock.now()
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panic while holding the lock cannot leave these queues inconsistent; keep going.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// One node on an [`InProcessBus`].
pub struct InProcessEndpoint {
    shared: Arc<Shared>,
    inbox: Arc<Inbox>,
}

impl InProcessEndpoint {
    /// Frames dropped because this endpoint's queue overflowed.
    pub fn dropped(&self) -> u64 {
        self.inbox.dropped.load(Ordering::Relaxed)
    }

    /// Delivers a frame to every node (synchronous; never blocks).
    pub fn transmit(&self, frame: CanFrame) {
        let rx = Received {
            frame,
            timestamp: self.shared.clock.now(),
        };
        let inboxes = lock(&self.shared.inboxes).clone();
        for ib in inboxes {
            if ib.id == self.inbox.id && !ib.own_echo {
                continue;
            }
            {
                let mut q = lock(&ib.queue);
                if q.len() >= ib.capacity {
                    q.pop_front();
                    ib.dropped.fetch_add(1, Ordering::Relaxed);
                }
                q.push_back(rx);
            }
            ib.notify.notify_one();
        }
    }

    fn pop(&self) -> Option<Received> {
        lock(&self.inbox.queue).pop_front()
    }
}

impl Drop for InProcessEndpoint {
    fn drop(&mut self) {
        lock(&self.shared.inboxes).retain(|ib| ib.id != self.inbox.id);
    }
}

impl Bus for InProcessEndpoint {
    fn send(&mut self, frame: CanFrame) -> impl Future<Output = Result<(), BusError>> + Send {
        self.transmit(frame);
        std::future::ready(Ok(()))
    }

    fn recv(&mut self) -> impl Future<Output = Result<Received, BusError>> + Send {
        let inbox = self.inbox.clone();
        async move {
            loop {
                let notified = inbox.notify.notified();
                if let Some(r) = lock(&inbox.queue).pop_front() {
                    return Ok(r);
                }
                notified.await;
            }
        }
    }

    fn try_recv(&mut self) -> Result<Option<Received>, BusError> {
        Ok(self.pop())
    }

    fn iface(&self) -> &str {
        &self.shared.name
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame the bus cannot represent is an error of that frame, with its reason kept as the
    /// cause; an I/O error is the bus's.
    #[test]
    fn a_bad_frame_is_frame_level_and_keeps_its_reason() {
        let e = BusError::BadFrame {
            iface: "vcan0".into(),
            source: crate::can::frame::FrameError::TooLong { len: 12 },
        };
        assert!(e.is_frame_level());
        assert_eq!(
            crate::error_chain::chain(&e),
            "CAN interface vcan0: a received frame cannot be represented: \
             12 data bytes exceed the classic CAN maximum of 8"
        );
        let io = BusError::Io {
            iface: "vcan0".into(),
            source: std::io::Error::other("down"),
        };
        assert!(!io.is_frame_level());
    }

    fn f(id: u16, b: u8) -> CanFrame {
        CanFrame::standard(id, &[b]).unwrap()
    }

    #[test]
    fn nodes_see_each_other_not_themselves() {
        let clock = Arc::new(ManualClock::new(Duration::from_secs(5)));
        let bus = InProcessBus::with_clock("sim", clock.clone());
        let mut a = bus.endpoint(EndpointConfig::default());
        let mut b = bus.endpoint(EndpointConfig::default());
        let mut c = bus.endpoint(EndpointConfig {
            own_echo: true,
            ..Default::default()
        });
        a.transmit(f(1, 1));
        clock.advance(Duration::from_millis(3));
        c.transmit(f(2, 2));
        assert_eq!(a.try_recv().unwrap().map(|r| r.frame), Some(f(2, 2)));
        assert_eq!(a.try_recv().unwrap(), None);
        let rb: Vec<_> = std::iter::from_fn(|| b.try_recv().unwrap()).collect();
        assert_eq!(
            rb.iter().map(|r| r.frame).collect::<Vec<_>>(),
            vec![f(1, 1), f(2, 2)]
        );
        assert_eq!(rb[0].timestamp, Duration::from_secs(5));
        assert_eq!(rb[1].timestamp, Duration::from_millis(5003));
        let rc: Vec<_> = std::iter::from_fn(|| c.try_recv().unwrap())
            .map(|r| r.frame)
            .collect();
        assert_eq!(rc, vec![f(1, 1), f(2, 2)], "own echo on");
    }

    #[test]
    fn overflow_drops_oldest_and_counts() {
        let bus = InProcessBus::new("sim");
        let a = bus.endpoint(EndpointConfig::default());
        let mut b = bus.endpoint(EndpointConfig {
            own_echo: false,
            queue: 2,
        });
        for i in 0..5 {
            a.transmit(f(1, i));
        }
        assert_eq!(b.dropped(), 3);
        assert_eq!(b.try_recv().unwrap().unwrap().frame, f(1, 3));
    }

    #[tokio::test]
    async fn async_recv_wakes_up() {
        let bus = InProcessBus::new("sim");
        let mut a = bus.endpoint(EndpointConfig::default());
        let mut b = bus.endpoint(EndpointConfig::default());
        let h = tokio::spawn(async move { b.recv().await.unwrap().frame });
        tokio::time::sleep(Duration::from_millis(5)).await;
        a.send(f(7, 7)).await.unwrap();
        assert_eq!(h.await.unwrap(), f(7, 7));
    }
}

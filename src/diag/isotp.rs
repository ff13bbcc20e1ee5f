//! ISO 15765-2 (ISO-TP) transport on classic CAN, one connection (a transmit and a receive id),
//! as a pure core in the style of the TCU's: time is an argument, nothing here reads a clock or
//! touches a socket. The shell feeds received frames ([`IsoTp::handle_frame`]), asks for frames to
//! send ([`IsoTp::poll_transmit`]) and wakes the core at [`IsoTp::poll_timeout`].
//!
//! Frames (the protocol control information in the first byte's high nibble):
//!
//! | PCI | frame | layout |
//! |---|---|---|
//! | 0 | single (SF) | `0L` + L ≤ 7 data bytes |
//! | 1 | first (FF) | `1L LL` (12-bit length, 8 ..= 4095) + 6 data bytes |
//! | 2 | consecutive (CF) | `2N` (sequence number N, 1, 2, … 15, 0, …) + up to 7 data bytes |
//! | 3 | flow control (FC) | `3S BS ST`: S = 0 continue, 1 wait, 2 overflow; BS block size (0: no further FC); ST the separation time STmin |
//!
//! STmin: 0x00–0x7F ms, 0xF1–0xF9 100–900 µs; a reserved value counts as 0x7F (127 ms). The
//! sender waits N_Bs for each flow control, the receiver N_Cr for each consecutive frame; on
//! expiry the transfer is abandoned and counted. A new first or single frame during a reception
//! abandons it and starts the new one (ISO 15765-2 9.8.3). Malformed frames, consecutive frames
//! out of sequence or unexpected, and flow controls nobody waits for are dropped and counted,
//! never a panic.

use std::collections::VecDeque;
use std::time::Duration;

/// Largest payload of a classic-CAN ISO-TP message (12-bit length).
pub const MAX_PAYLOAD: usize = 4095;

/// Largest single-frame payload on classic CAN.
const SF_MAX: usize = 7;

/// Data bytes in a first frame.
const FF_DATA: usize = 6;

/// Data bytes in a consecutive frame.
const CF_DATA: usize = 7;

/// The settings of one connection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IsoTpConfig {
    /// Block size this side asks of a sender (0: all consecutive frames without further FC).
    pub block_size: u8,
    /// STmin this side asks of a sender (the raw byte: 0x00–0x7F ms, 0xF1–0xF9 100–900 µs).
    pub st_min: u8,
    /// The byte frames are padded with to 8 bytes; `None`: frames as short as their content.
    pub padding: Option<u8>,
    /// N_Bs: how long the sender waits for a flow control.
    pub n_bs: Duration,
    /// N_Cr: how long the receiver waits for the next consecutive frame.
    pub n_cr: Duration,
    /// How many flow controls "wait" in a row the sender accepts before it gives up (N_WFTmax).
    pub max_wait_frames: u8,
}

impl Default for IsoTpConfig {
    /// The usual values: no block limit, no separation time, padding 0xCC, 1 s timeouts.
    fn default() -> Self {
        IsoTpConfig {
            block_size: 0,
            st_min: 0,
            padding: Some(0xCC),
            n_bs: Duration::from_millis(1000),
            n_cr: Duration::from_millis(1000),
            max_wait_frames: 10,
        }
    }
}

/// Why [`IsoTp::send`] refused a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SendError {
    #[error("an ISO-TP message needs at least one byte")]
    Empty,
    #[error("an ISO-TP message on classic CAN holds at most {MAX_PAYLOAD} bytes, not {0}")]
    TooLong(usize),
    #[error("a transmission is still in progress")]
    Busy,
}

/// What happened to a transfer the core abandoned or refused, counted in [`Counters`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Dropped {
    /// A frame too short, with an unknown PCI or an impossible length.
    Malformed,
    /// A consecutive frame with the wrong sequence number (the reception is abandoned).
    WrongSequence,
    /// A consecutive frame with no reception in progress.
    UnexpectedConsecutive,
    /// A flow control with no transmission waiting for one.
    UnexpectedFlowControl,
    /// A multi-frame message on the functional address (single frames only).
    FunctionalMultiFrame,
}

/// Counts of the connection's traffic and faults.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Counters {
    pub messages_received: u64,
    pub messages_sent: u64,
    pub malformed: u64,
    pub wrong_sequence: u64,
    pub unexpected_consecutive: u64,
    pub unexpected_flow_control: u64,
    pub functional_multi_frame: u64,
    /// Receptions abandoned because a new first or single frame came.
    pub receptions_interrupted: u64,
    /// N_Cr expired: a reception abandoned.
    pub rx_timeouts: u64,
    /// N_Bs expired: a transmission abandoned.
    pub tx_timeouts: u64,
    /// Transmissions abandoned on an overflow flow control or too many waits.
    pub tx_aborted: u64,
    /// First frames refused with an overflow flow control (longer than [`MAX_PAYLOAD`]).
    pub overflows_sent: u64,
}

impl Counters {
    fn count(&mut self, d: Dropped) {
        match d {
            Dropped::Malformed => self.malformed += 1,
            Dropped::WrongSequence => self.wrong_sequence += 1,
            Dropped::UnexpectedConsecutive => self.unexpected_consecutive += 1,
            Dropped::UnexpectedFlowControl => self.unexpected_flow_control += 1,
            Dropped::FunctionalMultiFrame => self.functional_multi_frame += 1,
        }
    }
}

/// Flow status of a flow control.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum FlowStatus {
    ContinueToSend,
    Wait,
    Overflow,
}

/// One frame's meaning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pci<'a> {
    Single(&'a [u8]),
    First {
        len: usize,
        data: &'a [u8],
    },
    Consecutive {
        sn: u8,
        data: &'a [u8],
    },
    Flow {
        status: FlowStatus,
        bs: u8,
        st_min: u8,
    },
}

/// Parses a frame's payload; `None` when it is not a valid ISO-TP frame on classic CAN.
fn parse(frame: &[u8]) -> Option<Pci<'_>> {
    let (&b0, rest) = frame.split_first()?;
    match b0 >> 4 {
        0 => {
            let len = usize::from(b0 & 0x0F);
            (1..=SF_MAX.min(rest.len()))
                .contains(&len)
                .then(|| Pci::Single(&rest[..len]))
        }
        1 => {
            let (&b1, data) = rest.split_first()?;
            let len = usize::from(b0 & 0x0F) << 8 | usize::from(b1);
            (len > SF_MAX && data.len() >= FF_DATA).then(|| Pci::First {
                len,
                data: &data[..FF_DATA],
            })
        }
        2 => (!rest.is_empty()).then_some(Pci::Consecutive {
            sn: b0 & 0x0F,
            data: rest,
        }),
        3 => {
            let status = match b0 & 0x0F {
                0 => FlowStatus::ContinueToSend,
                1 => FlowStatus::Wait,
                2 => FlowStatus::Overflow,
                _ => return None,
            };
            let (&bs, rest) = rest.split_first()?;
            let (&st_min, _) = rest.split_first()?;
            Some(Pci::Flow { status, bs, st_min })
        }
        _ => None,
    }
}

/// The separation time a raw STmin byte asks for (reserved values count as 127 ms).
pub(crate) fn st_min_duration(raw: u8) -> Duration {
    match raw {
        0x00..=0x7F => Duration::from_millis(u64::from(raw)),
        0xF1..=0xF9 => Duration::from_micros(100 * u64::from(raw - 0xF0)),
        _ => Duration::from_millis(0x7F),
    }
}

/// A frame to send: up to 8 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TxFrame {
    pub data: [u8; 8],
    pub len: usize,
}

impl TxFrame {
    /// The frame's bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.data[..self.len]
    }
}

/// A reception in progress.
#[derive(Debug, Clone, PartialEq)]
struct Rx {
    buf: Vec<u8>,
    len: usize,
    next_sn: u8,
    /// Consecutive frames left in the block before this side sends the next flow control.
    block_left: u8,
    deadline: Duration,
}

/// A transmission in progress.
#[derive(Debug, Clone, PartialEq)]
struct Tx {
    payload: Vec<u8>,
    /// Bytes already sent.
    pos: usize,
    next_sn: u8,
    /// When the last consecutive frame went out: STmin holds across a flow control too.
    last_cf: Option<Duration>,
    state: TxState,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum TxState {
    /// Waiting for a flow control until `deadline` (after `waits` flow controls "wait").
    AwaitFlow { deadline: Duration, waits: u8 },
    /// Sending consecutive frames: the next at `next_at`, `block_left` before the next flow
    /// control (`None`: no limit), `st_min` apart.
    Sending {
        next_at: Duration,
        block_left: Option<u8>,
        st_min: Duration,
    },
}

/// One ISO-TP connection: the transmit side and the receive side.
#[derive(Debug, Clone)]
pub struct IsoTp {
    cfg: IsoTpConfig,
    rx: Option<Rx>,
    tx: Option<Tx>,
    /// Frames queued to go out at once (single and first frames, flow controls).
    out: VecDeque<TxFrame>,
    /// The last frame [`IsoTp::poll_transmit`] gave was a consecutive frame whose send time
    /// [`IsoTp::sent`] has not reported yet.
    cf_unconfirmed: bool,
    counters: Counters,
}

impl IsoTp {
    /// An idle connection.
    pub fn new(cfg: IsoTpConfig) -> Self {
        IsoTp {
            cfg,
            rx: None,
            tx: None,
            out: VecDeque::new(),
            cf_unconfirmed: false,
            counters: Counters::default(),
        }
    }

    /// The traffic and fault counts.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Whether a transmission is in progress.
    pub fn sending(&self) -> bool {
        self.tx.is_some()
    }

    /// Abandons the transmission in progress, if any (counted as aborted): a new response
    /// replaces it.
    pub fn abort_send(&mut self) {
        if self.tx.take().is_some() {
            self.counters.tx_aborted += 1;
        }
    }

    /// Starts sending `payload` at `now`: a single frame, or a first frame and then consecutive
    /// frames as the receiver's flow controls allow.
    pub fn send(&mut self, now: Duration, payload: &[u8]) -> Result<(), SendError> {
        if payload.is_empty() {
            return Err(SendError::Empty);
        }
        if payload.len() > MAX_PAYLOAD {
            return Err(SendError::TooLong(payload.len()));
        }
        if self.tx.is_some() {
            return Err(SendError::Busy);
        }
        if payload.len() <= SF_MAX {
            self.queue(&[payload.len() as u8], payload);
            self.counters.messages_sent += 1;
            return Ok(());
        }
        let len = payload.len();
        self.queue(&[0x10 | (len >> 8) as u8, len as u8], &payload[..FF_DATA]);
        self.tx = Some(Tx {
            payload: payload.to_vec(),
            pos: FF_DATA,
            next_sn: 1,
            last_cf: None,
            state: TxState::AwaitFlow {
                deadline: now + self.cfg.n_bs,
                waits: 0,
            },
        });
        Ok(())
    }

    /// A frame received at `now` on the connection's (physical) receive id; returns a message
    /// when it completes one.
    pub fn handle_frame(&mut self, now: Duration, frame: &[u8]) -> Option<Vec<u8>> {
        let Some(pci) = parse(frame) else {
            self.counters.count(Dropped::Malformed);
            return None;
        };
        match pci {
            Pci::Single(data) => {
                self.interrupt_reception();
                self.counters.messages_received += 1;
                Some(data.to_vec())
            }
            Pci::First { len, data } => {
                self.interrupt_reception();
                self.first_frame(now, len, data);
                None
            }
            Pci::Consecutive { sn, data } => self.consecutive_frame(now, sn, data),
            Pci::Flow { status, bs, st_min } => {
                self.flow_control(now, status, bs, st_min);
                None
            }
        }
    }

    /// A frame received at `now` on the functional address: single frames only (a functional
    /// request is never segmented); a reception in progress on the physical address goes on.
    pub fn handle_functional(&mut self, frame: &[u8]) -> Option<Vec<u8>> {
        match parse(frame) {
            Some(Pci::Single(data)) => {
                self.counters.messages_received += 1;
                Some(data.to_vec())
            }
            Some(_) => {
                self.counters.count(Dropped::FunctionalMultiFrame);
                None
            }
            None => {
                self.counters.count(Dropped::Malformed);
                None
            }
        }
    }

    /// The next frame to send at `now`, if one is due: queued frames first, then the next
    /// consecutive frame once its separation time has passed.
    pub fn poll_transmit(&mut self, now: Duration) -> Option<TxFrame> {
        self.cf_unconfirmed = false;
        if let Some(f) = self.out.pop_front() {
            return Some(f);
        }
        let tx = self.tx.as_mut()?;
        let TxState::Sending {
            next_at,
            block_left,
            st_min,
        } = tx.state
        else {
            return None;
        };
        if now < next_at {
            return None;
        }
        let end = (tx.pos + CF_DATA).min(tx.payload.len());
        let f = frame(
            self.cfg.padding,
            &[0x20 | tx.next_sn],
            &tx.payload[tx.pos..end],
        );
        tx.pos = end;
        tx.next_sn = (tx.next_sn + 1) & 0x0F;
        tx.last_cf = Some(now);
        self.cf_unconfirmed = true;
        let done = tx.pos == tx.payload.len();
        let block_left = block_left.map(|b| b - 1);
        tx.state = if block_left == Some(0) && !done {
            TxState::AwaitFlow {
                deadline: now + self.cfg.n_bs,
                waits: 0,
            }
        } else {
            TxState::Sending {
                next_at: now + st_min,
                block_left,
                st_min,
            }
        };
        if done {
            self.tx = None;
            self.counters.messages_sent += 1;
        }
        Some(f)
    }

    /// The frame the last [`IsoTp::poll_transmit`] gave left at `at` (read after the write
    /// returned). STmin then counts from there, not from the `now` the frame was taken at: a
    /// shell delayed between taking a consecutive frame and writing it would otherwise send the
    /// next one early. Other frames, and a transfer already complete, need nothing.
    pub fn sent(&mut self, at: Duration) {
        if !std::mem::take(&mut self.cf_unconfirmed) {
            return;
        }
        let Some(tx) = self.tx.as_mut() else {
            return;
        };
        tx.last_cf = tx.last_cf.map(|t| t.max(at));
        if let TxState::Sending {
            next_at, st_min, ..
        } = &mut tx.state
        {
            *next_at = (*next_at).max(at + *st_min);
        }
    }

    /// When the core next needs to run without a received frame: at once when a frame is
    /// queued, at the next consecutive frame's time, or at the earliest N_Bs / N_Cr deadline.
    pub fn poll_timeout(&self) -> Option<Duration> {
        if !self.out.is_empty() {
            return Some(Duration::ZERO);
        }
        let tx = self.tx.as_ref().map(|tx| match tx.state {
            TxState::AwaitFlow { deadline, .. } => deadline,
            TxState::Sending { next_at, .. } => next_at,
        });
        let rx = self.rx.as_ref().map(|rx| rx.deadline);
        match (tx, rx) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Abandons, at `now`, a transfer whose N_Bs or N_Cr has expired.
    pub fn handle_timeout(&mut self, now: Duration) {
        if self.rx.as_ref().is_some_and(|rx| now >= rx.deadline) {
            self.rx = None;
            self.counters.rx_timeouts += 1;
        }
        if let Some(Tx {
            state: TxState::AwaitFlow { deadline, .. },
            ..
        }) = self.tx
        {
            if now >= deadline {
                self.tx = None;
                self.counters.tx_timeouts += 1;
            }
        }
    }

    /// A first frame of `len` bytes: refused with an overflow flow control when too long for
    /// classic CAN, else a reception starts and the first flow control goes out.
    fn first_frame(&mut self, now: Duration, len: usize, data: &[u8]) {
        if len > MAX_PAYLOAD {
            self.counters.overflows_sent += 1;
            self.queue(&[0x32, 0, 0], &[]);
            return;
        }
        let mut buf = Vec::with_capacity(len);
        buf.extend_from_slice(data);
        self.rx = Some(Rx {
            buf,
            len,
            next_sn: 1,
            block_left: self.cfg.block_size,
            deadline: now + self.cfg.n_cr,
        });
        self.queue_continue();
    }

    /// A consecutive frame: appended when it is the one expected (the reception is abandoned
    /// on a wrong sequence number); a flow control after each full block; the message when
    /// complete.
    fn consecutive_frame(&mut self, now: Duration, sn: u8, data: &[u8]) -> Option<Vec<u8>> {
        let Some(rx) = self.rx.as_mut() else {
            self.counters.count(Dropped::UnexpectedConsecutive);
            return None;
        };
        if sn != rx.next_sn {
            self.rx = None;
            self.counters.count(Dropped::WrongSequence);
            return None;
        }
        let take = (rx.len - rx.buf.len()).min(data.len());
        rx.buf.extend_from_slice(&data[..take]);
        rx.next_sn = (rx.next_sn + 1) & 0x0F;
        rx.deadline = now + self.cfg.n_cr;
        if rx.buf.len() == rx.len {
            let msg = std::mem::take(&mut rx.buf);
            self.rx = None;
            self.counters.messages_received += 1;
            return Some(msg);
        }
        if self.cfg.block_size > 0 {
            rx.block_left -= 1;
            if rx.block_left == 0 {
                rx.block_left = self.cfg.block_size;
                self.queue_continue();
            }
        }
        None
    }

    /// A flow control for the transmission waiting for one: continue (with the receiver's
    /// block size and STmin), wait (up to `max_wait_frames` in a row) or overflow (abandon).
    fn flow_control(&mut self, now: Duration, status: FlowStatus, bs: u8, st_min: u8) {
        let Some(tx) = self.tx.as_mut() else {
            self.counters.count(Dropped::UnexpectedFlowControl);
            return;
        };
        let TxState::AwaitFlow { waits, .. } = tx.state else {
            self.counters.count(Dropped::UnexpectedFlowControl);
            return;
        };
        match status {
            FlowStatus::ContinueToSend => {
                let st_min = st_min_duration(st_min);
                tx.state = TxState::Sending {
                    next_at: tx.last_cf.map_or(now, |t| (t + st_min).max(now)),
                    block_left: (bs > 0).then_some(bs),
                    st_min,
                };
            }
            FlowStatus::Wait if waits < self.cfg.max_wait_frames => {
                tx.state = TxState::AwaitFlow {
                    deadline: now + self.cfg.n_bs,
                    waits: waits + 1,
                };
            }
            FlowStatus::Wait | FlowStatus::Overflow => {
                self.tx = None;
                self.counters.tx_aborted += 1;
            }
        }
    }

    /// A new first or single frame abandons the reception in progress.
    fn interrupt_reception(&mut self) {
        if self.rx.take().is_some() {
            self.counters.receptions_interrupted += 1;
        }
    }

    /// Queues a flow control "continue to send" with this side's block size and STmin.
    fn queue_continue(&mut self) {
        let fc = [0x30, self.cfg.block_size, self.cfg.st_min];
        self.queue(&fc, &[]);
    }

    /// Queues the frame of `pci` and `data`.
    fn queue(&mut self, pci: &[u8], data: &[u8]) {
        let f = frame(self.cfg.padding, pci, data);
        self.out.push_back(f);
    }
}

/// The frame of the protocol control bytes `pci` and then `data` (8 bytes at most in all),
/// padded to 8 with `padding` when there is one; no allocation.
fn frame(padding: Option<u8>, pci: &[u8], data: &[u8]) -> TxFrame {
    let len = pci.len() + data.len();
    let mut bytes = [padding.unwrap_or(0); 8];
    bytes[..pci.len()].copy_from_slice(pci);
    bytes[pci.len()..len].copy_from_slice(data);
    TxFrame {
        data: bytes,
        len: if padding.is_some() { 8 } else { len },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    /// Runs a transfer of `payload` from `a` to `b` in simulated time, 0.1 ms steps, until both
    /// are idle or `limit` passes; returns what `b` received and the send times of every frame
    /// from `a`.
    fn transfer(
        a: &mut IsoTp,
        b: &mut IsoTp,
        payload: &[u8],
        limit: Duration,
    ) -> (Option<Vec<u8>>, Vec<(Duration, TxFrame)>) {
        let step = Duration::from_micros(100);
        let mut now = Duration::ZERO;
        a.send(now, payload).unwrap();
        let mut got = None;
        let mut sent = Vec::new();
        while now < limit {
            while let Some(f) = a.poll_transmit(now) {
                sent.push((now, f));
                if let Some(m) = b.handle_frame(now, f.bytes()) {
                    got = Some(m);
                }
            }
            while let Some(f) = b.poll_transmit(now) {
                a.handle_frame(now, f.bytes());
            }
            a.handle_timeout(now);
            b.handle_timeout(now);
            if got.is_some() && !a.sending() {
                break;
            }
            now += step;
        }
        (got, sent)
    }

    fn payload(n: usize) -> Vec<u8> {
        (0..n).map(|i| (i * 7 + 3) as u8).collect()
    }

    #[test]
    fn single_frame_is_padded_and_read_back() {
        let mut a = IsoTp::new(IsoTpConfig::default());
        a.send(Duration::ZERO, &[0x22, 0xF1, 0x90]).unwrap();
        let f = a.poll_transmit(Duration::ZERO).unwrap();
        assert_eq!(f.bytes(), &[0x03, 0x22, 0xF1, 0x90, 0xCC, 0xCC, 0xCC, 0xCC]);
        let mut b = IsoTp::new(IsoTpConfig {
            padding: None,
            ..IsoTpConfig::default()
        });
        assert_eq!(
            b.handle_frame(Duration::ZERO, f.bytes()),
            Some(vec![0x22, 0xF1, 0x90])
        );
        b.send(Duration::ZERO, &[0x62]).unwrap();
        assert_eq!(
            b.poll_transmit(Duration::ZERO).unwrap().bytes(),
            &[0x01, 0x62]
        );
    }

    #[test]
    fn multi_frame_transfers_honour_block_size_and_st_min() {
        for bs in [0u8, 1, 8] {
            for st in [0u8, 5, 20] {
                let n = 100;
                let mut a = IsoTp::new(IsoTpConfig::default());
                let mut b = IsoTp::new(IsoTpConfig {
                    block_size: bs,
                    st_min: st,
                    ..IsoTpConfig::default()
                });
                let (got, sent) = transfer(&mut a, &mut b, &payload(n), Duration::from_secs(5));
                assert_eq!(got.as_deref(), Some(&payload(n)[..]), "bs {bs} st {st}");
                // FF + ceil((100 − 6) / 7) = 14 CFs.
                assert_eq!(sent.len(), 1 + 14);
                let cfs: Vec<Duration> = sent[1..].iter().map(|(t, _)| *t).collect();
                for w in cfs.windows(2) {
                    assert!(w[1] - w[0] >= ms(u64::from(st)), "bs {bs} st {st}: {w:?}");
                }
                // Sequence numbers 1, 2, … wrapping after 15.
                for (k, (_, f)) in sent[1..].iter().enumerate() {
                    assert_eq!(f.data[0], 0x20 | ((k + 1) & 0x0F) as u8);
                }
                assert_eq!(a.counters().messages_sent, 1);
                assert_eq!(b.counters().messages_received, 1);
            }
        }
    }

    #[test]
    fn st_min_counts_from_when_the_shell_wrote_the_frame() {
        for bs in [0u8, 1] {
            let mut a = IsoTp::new(IsoTpConfig::default());
            a.send(Duration::ZERO, &payload(30)).unwrap();
            a.poll_transmit(Duration::ZERO).unwrap(); // FF
            a.handle_frame(ms(1), &[0x30, bs, 5]);
            assert!(a.poll_transmit(ms(1)).is_some(), "first CF at once");
            // The shell took the CF at 1 ms but its write returned only at 3 ms.
            a.sent(ms(3));
            if bs == 1 {
                a.handle_frame(ms(4), &[0x30, bs, 5]);
            }
            assert_eq!(
                a.poll_transmit(ms(7)),
                None,
                "bs {bs}: 5 ms from the write, not the take"
            );
            assert_eq!(a.poll_timeout(), Some(ms(8)), "bs {bs}");
            assert!(a.poll_transmit(ms(8)).is_some(), "bs {bs}");
        }
        // A report after a single frame or a flow control changes nothing.
        let mut b = IsoTp::new(IsoTpConfig::default());
        b.send(Duration::ZERO, &[0x3E, 0]).unwrap();
        b.poll_transmit(Duration::ZERO).unwrap();
        b.sent(ms(50));
        assert!(!b.sending());
    }

    #[test]
    fn the_sender_waits_for_a_flow_control_after_each_block() {
        let mut a = IsoTp::new(IsoTpConfig::default());
        a.send(Duration::ZERO, &payload(40)).unwrap();
        assert_eq!(
            a.poll_transmit(Duration::ZERO).unwrap().data[..2],
            [0x10, 40]
        );
        assert_eq!(a.poll_transmit(ms(100)), None, "no CF before the FC");
        a.handle_frame(ms(1), &[0x30, 2, 0]);
        assert!(a.poll_transmit(ms(1)).is_some());
        assert!(a.poll_transmit(ms(1)).is_some());
        assert_eq!(a.poll_transmit(ms(2)), None, "block of 2 sent: waits");
        a.handle_frame(ms(3), &[0x30, 0, 0]);
        let rest: Vec<_> = std::iter::from_fn(|| a.poll_transmit(ms(3))).collect();
        // 40 − 6 − 14 = 20 bytes: 3 more CFs.
        assert_eq!(rest.len(), 3);
        assert!(!a.sending());
    }

    #[test]
    fn timeouts_abandon_transfers() {
        let cfg = IsoTpConfig::default();
        let mut a = IsoTp::new(cfg);
        a.send(Duration::ZERO, &payload(20)).unwrap();
        a.poll_transmit(Duration::ZERO);
        assert_eq!(a.poll_timeout(), Some(cfg.n_bs));
        a.handle_timeout(cfg.n_bs - ms(1));
        assert!(a.sending());
        a.handle_timeout(cfg.n_bs);
        assert!(!a.sending());
        assert_eq!(a.counters().tx_timeouts, 1);
        // Receiver: FF, one CF, then silence past N_Cr.
        let mut b = IsoTp::new(cfg);
        b.handle_frame(Duration::ZERO, &[0x10, 20, 1, 2, 3, 4, 5, 6]);
        assert_eq!(
            b.poll_transmit(Duration::ZERO).unwrap().data[..3],
            [0x30, 0, 0]
        );
        b.handle_frame(ms(10), &[0x21, 7, 8, 9, 10, 11, 12, 13]);
        assert_eq!(b.poll_timeout(), Some(ms(10) + cfg.n_cr));
        b.handle_timeout(ms(10) + cfg.n_cr);
        assert_eq!(b.counters().rx_timeouts, 1);
        assert_eq!(
            b.handle_frame(ms(1100), &[0x22, 14, 15, 16, 17, 18, 19, 20]),
            None
        );
        assert_eq!(b.counters().unexpected_consecutive, 1);
    }

    #[test]
    fn malformed_and_out_of_order_frames_are_dropped_and_counted() {
        let mut b = IsoTp::new(IsoTpConfig::default());
        for f in [
            &[][..],
            &[0x00],
            &[0x08, 1, 2, 3, 4, 5, 6, 7],
            &[0x05, 1, 2],
            &[0x10, 5, 1, 2, 3, 4, 5, 6],
            &[0x10, 20, 1],
            &[0x34, 0, 0],
            &[0x30, 0],
            &[0x40, 1],
            &[0x20],
        ] {
            assert_eq!(b.handle_frame(Duration::ZERO, f), None, "{f:?}");
        }
        assert_eq!(b.counters().malformed, 10);
        b.handle_frame(Duration::ZERO, &[0x10, 20, 1, 2, 3, 4, 5, 6]);
        assert_eq!(b.handle_frame(ms(1), &[0x22, 0, 0, 0, 0, 0, 0, 0]), None);
        assert_eq!(b.counters().wrong_sequence, 1);
        assert_eq!(
            b.poll_timeout(),
            Some(Duration::ZERO),
            "the FC is still queued"
        );
        b.poll_transmit(ms(1));
        assert_eq!(b.poll_timeout(), None, "the reception was abandoned");
        b.handle_frame(ms(2), &[0x30, 0, 0]);
        assert_eq!(b.counters().unexpected_flow_control, 1);
    }

    #[test]
    fn a_new_first_frame_replaces_the_reception_and_an_overflow_abandons_the_transmission() {
        let mut b = IsoTp::new(IsoTpConfig {
            padding: None,
            ..IsoTpConfig::default()
        });
        b.handle_frame(Duration::ZERO, &[0x10, 20, 1, 2, 3, 4, 5, 6]);
        b.handle_frame(ms(1), &[0x10, 9, 9, 9, 9, 9, 9, 9]);
        assert_eq!(b.counters().receptions_interrupted, 1);
        assert_eq!(
            b.handle_frame(ms(2), &[0x21, 8, 7, 6]),
            Some(vec![9, 9, 9, 9, 9, 9, 8, 7, 6])
        );
        // A receiver's overflow flow control abandons the transmission.
        let mut a = IsoTp::new(IsoTpConfig::default());
        a.send(Duration::ZERO, &payload(50)).unwrap();
        a.poll_transmit(Duration::ZERO);
        a.handle_frame(ms(1), &[0x32, 0, 0]);
        assert!(!a.sending());
        assert_eq!(a.counters().tx_aborted, 1);
    }

    #[test]
    fn wait_flow_controls_are_honoured_up_to_the_limit() {
        let mut a = IsoTp::new(IsoTpConfig {
            max_wait_frames: 2,
            ..IsoTpConfig::default()
        });
        a.send(Duration::ZERO, &payload(20)).unwrap();
        a.poll_transmit(Duration::ZERO);
        a.handle_frame(ms(500), &[0x31, 0, 0]);
        assert_eq!(a.poll_timeout(), Some(ms(1500)), "each wait restarts N_Bs");
        a.handle_frame(ms(600), &[0x31, 0, 0]);
        assert!(a.sending());
        a.handle_frame(ms(700), &[0x31, 0, 0]);
        assert!(!a.sending());
        assert_eq!(a.counters().tx_aborted, 1);
    }

    #[test]
    fn st_min_encoding() {
        assert_eq!(st_min_duration(0), Duration::ZERO);
        assert_eq!(st_min_duration(20), ms(20));
        assert_eq!(st_min_duration(0xF1), Duration::from_micros(100));
        assert_eq!(st_min_duration(0xF9), Duration::from_micros(900));
        assert_eq!(st_min_duration(0x80), ms(127));
        assert_eq!(st_min_duration(0xFA), ms(127));
    }

    #[test]
    fn functional_requests_are_single_frames_only() {
        let mut b = IsoTp::new(IsoTpConfig::default());
        assert_eq!(
            b.handle_functional(&[0x02, 0x3E, 0x00]),
            Some(vec![0x3E, 0x00])
        );
        assert_eq!(b.handle_functional(&[0x10, 20, 1, 2, 3, 4, 5, 6]), None);
        assert_eq!(b.counters().functional_multi_frame, 1);
        assert_eq!(
            b.poll_transmit(Duration::ZERO),
            None,
            "no FC for a functional FF"
        );
    }

    #[test]
    fn the_largest_message_goes_through_and_a_larger_one_is_refused() {
        let mut a = IsoTp::new(IsoTpConfig::default());
        assert_eq!(
            a.send(Duration::ZERO, &payload(MAX_PAYLOAD + 1)),
            Err(SendError::TooLong(4096))
        );
        assert_eq!(a.send(Duration::ZERO, &[]), Err(SendError::Empty));
        let mut b = IsoTp::new(IsoTpConfig {
            block_size: 8,
            ..IsoTpConfig::default()
        });
        let (got, sent) = transfer(
            &mut a,
            &mut b,
            &payload(MAX_PAYLOAD),
            Duration::from_secs(5),
        );
        assert_eq!(got.map(|m| m.len()), Some(MAX_PAYLOAD));
        assert_eq!(sent[0].1.data[..2], [0x1F, 0xFF]);
        assert_eq!(a.send(Duration::ZERO, &[1]), Ok(()));
        assert_eq!(a.send(Duration::ZERO, &payload(9)), Ok(()));
        assert_eq!(a.send(Duration::ZERO, &payload(9)), Err(SendError::Busy));
    }
}

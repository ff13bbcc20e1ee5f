//! The SocketCAN bus: a raw CAN socket through the `socketcan` crate's tokio support, with kernel
//! receive timestamps (`SO_TIMESTAMPNS`) on every frame read, blocking or not. Needs a tokio
//! runtime with I/O enabled: [`SocketCanBus::open`] refuses with [`BusError::NoRuntime`] outside
//! one, and [`SocketCanBus::probe`] checks an interface with a blocking socket, no runtime needed.
//!
//! Frames already waiting are read in batches with `recvmmsg(2)` ([`Bus::try_recv_many`]), which
//! the `socketcan` crate does not offer: one system call for up to [`MMSG_BATCH`] frames. Under a
//! flood, and under User-Mode Linux where a system call costs tens of µs, the per-frame read was
//! most of a daemon's CPU.

use super::bus::{Bus, BusError, Received};
use super::frame::CanFrame;
use socketcan::{EmbeddedFrame, Frame as _, Socket as _, SocketOptions};
use std::future::Future;
use std::io;
use std::os::fd::{AsRawFd, BorrowedFd};
use std::time::{SystemTime, UNIX_EPOCH};

/// Frames per `recvmmsg` call at most.
pub const MMSG_BATCH: usize = 64;

/// Room for one `SCM_TIMESTAMPNS` control message (a `cmsghdr` and a `timespec`), 8-aligned.
const CMSG_ROOM: usize = 64;

/// One message slot of a `recvmmsg` batch: the frame and its control data.
#[repr(C, align(8))]
#[derive(Clone, Copy)]
struct Slot {
    frame: libc::can_frame,
    control: [u8; CMSG_ROOM],
}

/// A SocketCAN endpoint on one interface (e.g. `vcan0`).
pub struct SocketCanBus {
    socket: socketcan::tokio::CanSocket,
    /// The same socket (a duplicated descriptor, non-blocking like the original) for reads that
    /// must not wait: the tokio socket's `try_read_frame` gives no timestamp, and a frame read
    /// without its kernel timestamp would be placed at its reading time.
    now: socketcan::CanSocket,
    iface: String,
}

impl std::fmt::Debug for SocketCanBus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SocketCanBus")
            .field("iface", &self.iface)
            .finish()
    }
}

impl SocketCanBus {
    /// Opens a raw socket on `iface` with receive timestamps; `own_echo` also delivers this
    /// socket's own frames back to it. Must be called on the tokio runtime (with I/O) that will
    /// use the socket: outside one it is [`BusError::NoRuntime`], not the runtime's panic.
    pub fn open(iface: &str, own_echo: bool) -> Result<Self, BusError> {
        let io_err = |source: io::Error| BusError::Io {
            iface: iface.to_string(),
            source,
        };
        if tokio::runtime::Handle::try_current().is_err() {
            return Err(BusError::NoRuntime {
                iface: iface.to_string(),
            });
        }
        let socket = socketcan::tokio::CanSocket::open(iface).map_err(io_err)?;
        socket.set_recv_timestamp(true).map_err(io_err)?;
        socket.set_recv_own_msgs(own_echo).map_err(io_err)?;
        // SAFETY: the descriptor is open for the lifetime of `socket`; it is only borrowed to
        // duplicate it.
        let fd = unsafe { BorrowedFd::borrow_raw(socket.as_raw_fd()) };
        let now = socketcan::CanSocket::from(fd.try_clone_to_owned().map_err(io_err)?);
        Ok(Self {
            socket,
            now,
            iface: iface.to_string(),
        })
    }

    /// Checks that `iface` exists and takes a raw CAN socket, with a blocking socket that is
    /// closed again at once: for a command that must fail early, before it starts the threads
    /// and runtimes that open their own endpoints. Needs no runtime.
    pub fn probe(iface: &str) -> Result<(), BusError> {
        socketcan::CanSocket::open(iface)
            .map(drop)
            .map_err(|source| BusError::Io {
                iface: iface.to_string(),
                source,
            })
    }

    /// Receives only data frames with these standard ids (one kernel filter per id), so a daemon
    /// is not woken for frames it ignores — under User-Mode Linux every receive is expensive.
    pub fn set_filter_ids(&self, ids: &[u16]) -> Result<(), BusError> {
        let mask = libc::CAN_SFF_MASK | libc::CAN_EFF_FLAG | libc::CAN_RTR_FLAG;
        let filters: Vec<socketcan::CanFilter> = ids
            .iter()
            .map(|&id| socketcan::CanFilter::new(u32::from(id), mask))
            .collect();
        self.socket
            .set_filters(&filters)
            .map_err(|e| self.io_error(e))
    }

    /// Asks the kernel for a receive queue of `bytes` (`SO_RCVBUFFORCE` where permitted — root —
    /// else `SO_RCVBUF`, which the kernel caps at `net.core.rmem_max`), so a reader the host
    /// deschedules for a while (a recorder) loses no frame. Returns the size the kernel granted.
    pub fn set_recv_buffer(&self, bytes: usize) -> Result<usize, BusError> {
        let io_err = |e| self.io_error(e);
        let val = libc::c_int::try_from(bytes).unwrap_or(libc::c_int::MAX);
        self.socket
            .set_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, val)
            .or_else(|_| {
                self.socket
                    .set_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUF, val)
            })
            .map_err(io_err)?;
        let got = self
            .socket
            .get_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUF)
            .map_err(io_err)?;
        Ok(usize::try_from(got).unwrap_or(0))
    }

    /// Frames the kernel dropped because this socket's receive queue was full, since it was
    /// opened (`SO_MEMINFO`'s `SK_MEMINFO_DROPS`, the socket's `sk_drops`).
    pub fn kernel_drops(&self) -> Result<u64, BusError> {
        // asm-generic/socket.h (the same on x86, arm and riscv); libc has the offsets only.
        const SO_MEMINFO: libc::c_int = 55;
        let mut info = [0u32; libc::SK_MEMINFO_DROPS as usize + 1];
        let mut len = libc::socklen_t::try_from(std::mem::size_of_val(&info)).unwrap_or(0);
        // SAFETY: `info` is a writable buffer of `len` bytes that outlives the call; the
        // descriptor is open for the lifetime of `self.socket`.
        let rc = unsafe {
            libc::getsockopt(
                self.socket.as_raw_fd(),
                libc::SOL_SOCKET,
                SO_MEMINFO,
                info.as_mut_ptr().cast(),
                &mut len,
            )
        };
        if rc != 0 {
            return Err(self.io_error(io::Error::last_os_error()));
        }
        Ok(u64::from(info[libc::SK_MEMINFO_DROPS as usize]))
    }

    /// The receive timestamp (`SCM_TIMESTAMPNS`) among a received message's control messages.
    fn timestamp_of(hdr: &libc::msghdr) -> Option<SystemTime> {
        // SAFETY: `hdr` is a header the kernel filled in by `recvmmsg`: its control pointer and
        // length describe the slot's control buffer, which outlives this call; the CMSG macros
        // stay inside `msg_controllen`.
        unsafe {
            let mut c = libc::CMSG_FIRSTHDR(hdr);
            while !c.is_null() {
                if (*c).cmsg_level == libc::SOL_SOCKET && (*c).cmsg_type == libc::SCM_TIMESTAMPNS {
                    let ts = std::ptr::read_unaligned(libc::CMSG_DATA(c).cast::<libc::timespec>());
                    return Some(socketcan::timestamp::timespec_to_system_time(ts));
                }
                c = libc::CMSG_NXTHDR(hdr, c);
            }
        }
        None
    }

    /// An I/O error on this interface, with its source.
    fn io_error(&self, source: io::Error) -> BusError {
        BusError::Io {
            iface: self.iface.clone(),
            source,
        }
    }

    fn convert(&self, frame: socketcan::CanFrame, ts: SystemTime) -> Result<Received, BusError> {
        if let socketcan::CanFrame::Error(e) = &frame {
            return Err(BusError::ErrorFrame {
                iface: self.iface.clone(),
                id: e.raw_id(),
            });
        }
        let frame = CanFrame::from_frame(&frame).map_err(|source| BusError::BadFrame {
            iface: self.iface.clone(),
            source,
        })?;
        Ok(Received {
            frame,
            timestamp: ts.duration_since(UNIX_EPOCH).unwrap_or_default(),
        })
    }

    fn to_socketcan(&self, frame: &CanFrame) -> Result<socketcan::CanFrame, BusError> {
        let built = if embedded_can::Frame::is_remote_frame(frame) {
            socketcan::CanFrame::new_remote(
                embedded_can::Frame::id(frame),
                embedded_can::Frame::dlc(frame),
            )
        } else {
            socketcan::CanFrame::new(embedded_can::Frame::id(frame), frame.bytes())
        };
        built.ok_or_else(|| BusError::Unsupported {
            iface: self.iface.clone(),
            what: format!("frame {frame:?}"),
        })
    }
}

impl Bus for SocketCanBus {
    fn send(&mut self, frame: CanFrame) -> impl Future<Output = Result<(), BusError>> + Send {
        let converted = self.to_socketcan(&frame);
        async move {
            let f = converted?;
            self.socket
                .write_frame(f)
                .await
                .map_err(|e| self.io_error(e))
        }
    }

    // Written out (not `async fn`) so that the trait's `Send` bound on the future is visible.
    #[allow(clippy::manual_async_fn)]
    fn recv(&mut self) -> impl Future<Output = Result<Received, BusError>> + Send {
        async move {
            let (f, ts) = self
                .socket
                .read_frame_with_timestamp()
                .await
                .map_err(|e| self.io_error(e))?;
            self.convert(f, ts)
        }
    }

    fn try_recv(&mut self) -> Result<Option<Received>, BusError> {
        match self.now.read_frame_with_timestamp() {
            Ok((f, ts)) => self.convert(f, ts).map(Some),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => Ok(None),
            Err(e) => Err(self.io_error(e)),
        }
    }

    fn try_recv_many(&mut self, max: usize, out: &mut Vec<Result<Received, BusError>>) -> bool {
        let n = max.min(MMSG_BATCH);
        if n == 0 {
            return false;
        }
        // SAFETY: all-zero bytes are a valid `can_frame` and control buffer.
        let mut slots = [unsafe { std::mem::zeroed::<Slot>() }; MMSG_BATCH];
        let mut iov: [libc::iovec; MMSG_BATCH] = [libc::iovec {
            iov_base: std::ptr::null_mut(),
            iov_len: 0,
        }; MMSG_BATCH];
        // SAFETY: all-zero bytes are a valid `mmsghdr` (null pointers, zero lengths).
        let mut msgs: [libc::mmsghdr; MMSG_BATCH] = unsafe { std::mem::zeroed() };
        for i in 0..n {
            iov[i] = libc::iovec {
                iov_base: std::ptr::addr_of_mut!(slots[i].frame).cast(),
                iov_len: std::mem::size_of::<libc::can_frame>(),
            };
            let h = &mut msgs[i].msg_hdr;
            h.msg_iov = &mut iov[i];
            h.msg_iovlen = 1;
            h.msg_control = slots[i].control.as_mut_ptr().cast();
            h.msg_controllen = CMSG_ROOM as _;
        }
        // SAFETY: `msgs[..n]` point into `iov` and `slots`, which live until after the call and
        // are not moved meanwhile; the descriptor is open for the lifetime of `self.now`.
        let rc = unsafe {
            libc::recvmmsg(
                self.now.as_raw_fd(),
                msgs.as_mut_ptr(),
                n as libc::c_uint,
                libc::MSG_DONTWAIT,
                std::ptr::null_mut(),
            )
        };
        if rc < 0 {
            let e = io::Error::last_os_error();
            if e.kind() == io::ErrorKind::WouldBlock {
                return true;
            }
            out.push(Err(self.io_error(e)));
            return false;
        }
        let got = rc as usize;
        for i in 0..got {
            let h = &msgs[i].msg_hdr;
            let frame = socketcan::CanFrame::from(slots[i].frame);
            let received = if (msgs[i].msg_len as usize) < std::mem::size_of::<libc::can_frame>() {
                Err(BusError::Unsupported {
                    iface: self.iface.clone(),
                    what: format!("a {}-byte read (not a classic CAN frame)", msgs[i].msg_len),
                })
            } else {
                // A frame without its timestamp (the option off) is placed at its reading.
                let ts = Self::timestamp_of(h).unwrap_or_else(SystemTime::now);
                self.convert(frame, ts)
            };
            out.push(received);
        }
        got < n
    }

    fn iface(&self) -> &str {
        &self.iface
    }
}

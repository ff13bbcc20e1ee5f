"""Receiving from a python-can bus with the receiver's OWN losses counted, apart from the bus.

A frame can go missing on its way to a python receiver in two places: on the bus (the sender
skipped it, or it was lost on the wire: every receiver sees the gap, an E2E error) or in this
receiver (the kernel dropped it because the socket's receive queue was full while python was
busy: only this receiver misses it). The E2E alive counter alone cannot tell the two apart.

On a SocketCAN bus ``Receiver`` asks the kernel for its drop counter (``SO_RXQ_OVFL``: every
frame read carries, as ancillary data, how many frames the socket had dropped when this one was
queued) and reads the socket itself with ``recvmsg``: python-can 4.6's ``SocketcanBus.recv``
requests room for the timestamp only, so the drop count never reaches its caller. A frame's
count minus the previous frame's is the number of frames lost between the two, in queue order.
An error frame of the CAN controller reporting its own receive overflow (``CAN_ERR_CRTL`` /
``CAN_ERR_CRTL_RX_OVERFLOW``, real controllers only) is a local loss of unknown size. Other
python-can buses (``virtual``, vendor interfaces) have no receive queue of their own that could
overflow in python-can; there the losses are unknown (``lost`` is None).

    rx = Receiver(bus)
    checker = E2EChecker()
    while ...:
        msg = rx.recv(timeout=0.1)
        if msg is not None:
            verdict = checker.check(msg.arbitration_id, bytes(msg.data), lost=rx.lost)
            # "local_drop": a counter gap explained by this receiver's own losses, not the bus's
    rx.dropped   # frames the kernel dropped from this receiver's queue so far
"""

from __future__ import annotations

import errno
import select
import socket
import struct
import time
from typing import Optional

import can

# Linux <asm-generic/socket.h> (x86, arm, arm64, riscv, ...; the socket module lacks them).
SO_TIMESTAMPNS = 35
SO_RXQ_OVFL = 40
SO_MEMINFO = 55
SK_MEMINFO_DROPS = 8  # <linux/sock_diag.h>: the socket's sk_drops in SO_MEMINFO
SK_MEMINFO_VARS = 9

# <linux/can/error.h>: the controller's own receive buffer overflowed.
CAN_ERR_FLAG = 0x20000000
CAN_ERR_CRTL = 0x00000004
CAN_ERR_CRTL_RX_OVERFLOW = 0x01
CAN_EFF_FLAG = 0x80000000
CAN_RTR_FLAG = 0x40000000
CANFD_MTU = 72

# A controller overflow lost an unknown number of frames: it counts as at least this many (more
# than any alive-counter gap can show) in ``lost``, not in ``dropped``.
UNKNOWN_LOSS = 1 << 16

_TIMESPEC = struct.Struct("@ll")
_U32 = struct.Struct("@I")
_ANC_SIZE = socket.CMSG_SPACE(_TIMESPEC.size) + socket.CMSG_SPACE(_U32.size)
_FRAME = struct.Struct("=IBBBB")  # can_id, len, flags (FD), res0, res1 (then data)


def socketcan_socket(bus: can.BusABC) -> Optional[socket.socket]:
    """The raw CAN socket of a python-can SocketCAN bus (None for any other bus)."""
    try:
        from can.interfaces.socketcan import SocketcanBus
    except ImportError:  # pragma: no cover - python-can always ships it
        return None
    return bus.socket if isinstance(bus, SocketcanBus) else None


def kernel_drops(sock: socket.socket) -> Optional[int]:
    """The socket's drop counter now (SO_MEMINFO), None where the kernel does not say."""
    try:
        raw = sock.getsockopt(socket.SOL_SOCKET, SO_MEMINFO, 4 * SK_MEMINFO_VARS)
    except OSError:
        return None
    if len(raw) < 4 * (SK_MEMINFO_DROPS + 1):
        return None
    return struct.unpack_from("@I", raw, 4 * SK_MEMINFO_DROPS)[0]


class Receiver:
    """Frames from ``bus`` (``recv``), with what this receiver itself lost before each one.

    ``dropped``: frames the kernel dropped from this receiver's socket queue since the receiver
    was made, as of the last frame read (``dropped_now()`` also counts drops after it); None
    when the bus cannot tell (not SocketCAN, or a kernel without SO_RXQ_OVFL).
    ``overflows``: error frames in which the CAN controller reported its own receive overflow.
    ``lost``: a running measure of this receiver's losses for ``E2EChecker.check(lost=...)``:
    ``dropped`` plus ``UNKNOWN_LOSS`` per controller overflow; None when unknown.

    On SocketCAN the receiver reads the bus's socket itself (frames go to whoever reads first:
    do not also call ``bus.recv`` on the same bus); python-can's software filters apply when
    its kernel filters could not be set. ``rcvbuf``: set the socket's receive buffer (bytes;
    the kernel doubles it and enforces a minimum) — a small one makes drops easy to provoke."""

    def __init__(self, bus: can.BusABC, rcvbuf: Optional[int] = None):
        self.bus = bus
        self.socket = socketcan_socket(bus)
        self.dropped: Optional[int] = None
        self.overflows = 0
        self._base = 0
        if self.socket is not None:
            if rcvbuf is not None:
                self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, int(rcvbuf))
            # The count so far first: a frame queued after SO_RXQ_OVFL is on carries a count that
            # includes any drop in between; one queued before carries none (counted as _base).
            base = kernel_drops(self.socket) or 0
            try:
                self.socket.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
            except OSError:
                pass
            else:
                self._base = base
                self.dropped = 0
        self._channel = getattr(bus, "channel", None) or None

    @property
    def counts_drops(self) -> bool:
        return self.dropped is not None

    @property
    def lost(self) -> Optional[int]:
        if self.dropped is None:
            return None
        return self.dropped + UNKNOWN_LOSS * self.overflows

    def dropped_now(self) -> Optional[int]:
        """``dropped`` including frames dropped after the last one read (SO_MEMINFO)."""
        if self.dropped is None or self.socket is None:
            return self.dropped
        now = kernel_drops(self.socket)
        return self.dropped if now is None else max(self.dropped, now - self._base)

    # -- receiving ---------------------------------------------------------------------------

    def recv_frame(self, timeout: Optional[float]) -> Optional[tuple]:
        """The next data frame as ``(arbitration_id, data, is_extended_id, timestamp)``, or None
        after ``timeout`` s (None: wait for ever). Error and remote frames are consumed (a
        controller overflow is counted) and not returned. On a bus that is not SocketCAN this
        is ``bus.recv``."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            if self.socket is None:
                msg = self.bus.recv(left)
                if msg is None:
                    return None
                if msg.is_error_frame or msg.is_remote_frame:
                    continue
                return msg.arbitration_id, bytes(msg.data), msg.is_extended_id, msg.timestamp
            got = self._read()
            if got is None:  # the queue is empty: wait for the next frame
                try:
                    ready, _, _ = select.select([self.socket], [], [], left)
                except InterruptedError:
                    continue
                except OSError as e:
                    raise can.CanOperationError(f"Failed to receive: {e.strerror}", e.errno) from e
                if not ready:
                    return None
                continue
            if got is not False:
                return got
            if deadline is not None and time.monotonic() >= deadline:
                return None  # only frames that are not returned, until the time ran out

    def _read(self):
        """One non-blocking recvmsg: the frame tuple, None when the queue is empty, False for a
        frame that is not returned (error, remote, filtered out)."""
        try:
            cf, anc, _flags, _addr = self.socket.recvmsg(CANFD_MTU, _ANC_SIZE, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return None
        except OSError as e:
            if e.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                return None
            raise can.CanOperationError(f"Error receiving: {e.strerror}", e.errno) from e
        ts = 0.0
        raw_drops = None
        for level, kind, data in anc:
            if level != socket.SOL_SOCKET:
                continue
            if kind == SO_TIMESTAMPNS:
                sec, nsec = _TIMESPEC.unpack_from(data)
                ts = sec + nsec * 1e-9
            elif kind == SO_RXQ_OVFL:
                raw_drops = _U32.unpack_from(data)[0]
        if self.dropped is not None:
            # No count: none dropped yet, or queued before SO_RXQ_OVFL was on (counted in _base).
            self.dropped = max(self.dropped, (self._base if raw_drops is None else raw_drops) - self._base)
        can_id, length = _FRAME.unpack_from(cf)[:2]
        data = bytes(cf[8:8 + length])
        if can_id & CAN_ERR_FLAG:
            if can_id & CAN_ERR_CRTL and len(data) > 1 and data[1] & CAN_ERR_CRTL_RX_OVERFLOW:
                self.overflows += 1
            return False
        if can_id & CAN_RTR_FLAG:
            return False
        ext = bool(can_id & CAN_EFF_FLAG)
        frame = (can_id & 0x1FFFFFFF if ext else can_id & 0x7FF), data, ext, ts
        bus = self.bus
        if not getattr(bus, "_is_filtered", True) and getattr(bus, "filters", None):
            # python-can could not set its filters in the kernel: it filters in software.
            if not bus._matches_filters(self._message(frame, is_fd=len(cf) == CANFD_MTU)):
                return False
        return frame

    def _message(self, frame: tuple, is_fd: bool = False) -> can.Message:
        fid, data, ext, ts = frame
        return can.Message(timestamp=ts, arbitration_id=fid, is_extended_id=ext, data=data, is_fd=is_fd,
                           channel=self._channel if self.socket is not None else None)

    def recv(self, timeout: Optional[float] = None) -> Optional[can.Message]:
        """The next data frame as a python-can Message (None after ``timeout`` s)."""
        if self.socket is None:
            deadline = None if timeout is None else time.monotonic() + timeout
            while True:  # error and remote frames are not data: skipped as by recv_frame
                left = None if deadline is None else max(0.0, deadline - time.monotonic())
                msg = self.bus.recv(left)
                if msg is None or not (msg.is_error_frame or msg.is_remote_frame):
                    return msg
        got = self.recv_frame(timeout)
        return None if got is None else self._message(got, is_fd=len(got[1]) > 8)

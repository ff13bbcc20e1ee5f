"""A bus monitor: the latest decoded value of every DBC message, E2E-checked, from a background
thread, and waits on them.

    with Monitor(bus) as mon:
        seen = mon.wait_state("Drive", timeout=4.0)   # every message's latest values then
        assert seen, f"the TCU is in {mon.tcu_state()}"
        slip = seen["ENG_Status"]["EngSpeed"] - seen["DCT_Sensors"]["InShaft1Speed"]
    assert not mon.e2e_errors     # what the bus itself showed (CRC, length, counter)
    mon.dropped, mon.local_drops  # what the monitor itself lost (its socket's queue overflowed)
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from typing import Callable, Iterable, Optional

import can

from .dbc import choice, label, load_dbc, message
from .e2e import LOCAL_DROP, NOT_PROTECTED, OK, E2EChecker
from .rx import Receiver


class Monitor:
    """Receives from ``bus`` in a background thread. Each frame of a DBC message is E2E-checked
    (CRC and alive counter, ``E2EChecker``); a frame with a bad length or CRC is counted in
    ``e2e_errors`` and not decoded, a counter out of sequence is counted and still decoded.
    ``frames`` counts the decoded frames per message name.

    The monitor's own losses are kept apart from the bus's: on SocketCAN it reads the bus's
    socket itself with the kernel's drop counter on (``rx.Receiver``, SO_RXQ_OVFL), so a frame
    the kernel dropped because the monitor fell behind (a busy python process, a starved guest)
    is counted in ``dropped``, and a counter gap that such drops explain is counted in
    ``local_drops`` (message name -> gaps), not in ``e2e_errors``. ``e2e_errors`` then holds
    only what the bus itself shows: a CRC or length error, a counter skipped or repeated beyond
    what the monitor lost. On other buses (python-can's ``virtual``) ``dropped`` is None and
    every gap is an E2E error. Do not read the same bus object elsewhere while a monitor runs
    (each frame goes to one reader).

    ``messages``: only these (names); the monitor then sets kernel filters on ``bus`` for their
    IDs (``bus.set_filters``: this applies to everything that receives on that bus object), so
    that a small machine (a single-CPU User-Mode Linux guest) does not spend itself decoding
    frames nobody reads. Default: every message of the DBC, no filter."""

    def __init__(self, bus: can.BusABC, messages: Optional[Iterable[str]] = None):
        self.bus = bus
        if messages is not None:
            wanted = [message(m) for m in messages]
            bus.set_filters([{"can_id": m.frame_id, "can_mask": 0x7FF, "extended": False} for m in wanted])
        self.rx = Receiver(bus)
        self.frames: Counter = Counter()
        self.e2e_errors: Counter = Counter()  # (message name, verdict) -> count: the bus's errors
        self.local_drops: Counter = Counter()  # message name -> counter gaps the monitor's own drops explain
        self._by_id = {m.frame_id: m for m in load_dbc().messages}
        self._by_name = {m.name: m for m in self._by_id.values()}
        self._latest: dict[str, bytes] = {}
        self._cache: dict[str, tuple] = {}
        self._checker = E2EChecker()
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._error: Optional[BaseException] = None

    @property
    def dropped(self) -> Optional[int]:
        """Frames the kernel dropped from the monitor's receive queue since it was made (its own
        losses, not the bus's); None when the bus cannot tell (not SocketCAN)."""
        return self.rx.dropped_now()

    def start(self) -> "Monitor":
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="ddct-monitor", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._error is not None:
            raise RuntimeError(f"the monitor's receiver failed: {self._error!r}") from self._error

    def __enter__(self) -> "Monitor":
        return self.start()

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self.stop()
        except RuntimeError:
            if exc_type is None:
                raise

    def _run(self) -> None:
        try:
            rx = self.rx
            while not self._stop.is_set():
                got = rx.recv_frame(0.05)
                if got is not None:
                    self.feed(got[0], got[1], got[2], rx.lost)
        except BaseException as e:  # noqa: BLE001 - reported by stop() and the waits
            self._error = e
            with self._cond:
                self._cond.notify_all()

    def feed(self, frame_id: int, data: bytes, extended: bool = False, lost: Optional[int] = None) -> None:
        """Take one frame (the receiver thread calls this; a test may too). ``lost``: the
        receiver's own losses so far (``E2EChecker.check``)."""
        m = self._by_id.get(frame_id)
        if extended or m is None:
            return
        verdict = self._checker.check(frame_id, data, lost)
        if verdict == LOCAL_DROP:
            self.local_drops[m.name] += 1
        elif verdict not in (OK, NOT_PROTECTED):
            self.e2e_errors[(m.name, verdict)] += 1
            if len(data) != m.length or verdict == "bad_crc":
                return
        with self._cond:
            self._latest[m.name] = data  # decoded when asked for (most frames never are)
            self.frames[m.name] += 1
            self._cond.notify_all()

    def _decoded(self, name: str) -> dict:
        data = self._latest[name]
        hit = self._cache.get(name)
        if hit is None or hit[0] is not data:
            hit = (data, self._by_name[name].decode(data, decode_choices=False))
            self._cache[name] = hit
        return hit[1]

    def __getitem__(self, name: str) -> dict:
        """The latest signals of a message (raw numbers for value tables); KeyError if none yet."""
        with self._cond:
            if name not in self._latest:
                raise KeyError(f"no {name} frame received yet")
            return dict(self._decoded(name))

    def get(self, name: str, default=None):
        with self._cond:
            return dict(self._decoded(name)) if name in self._latest else default

    def tcu_state(self) -> Optional[str]:
        """The TCU's latest TcuState by name (None before the first TCU_Status)."""
        status = self.get("TCU_Status")
        return None if status is None else label("TCU_Status", "TcuState", status["TcuState"])

    def snapshot(self) -> dict:
        """{message name: latest signals} of every message seen so far."""
        with self._cond:
            return {k: dict(self._decoded(k)) for k in self._latest}

    def wait(self, predicate: Callable[["Monitor"], bool], timeout: float) -> Optional[dict]:
        """Wait until ``predicate(self)`` holds (checked after every decoded frame), at most
        ``timeout`` s: the ``snapshot()`` taken at that frame (so the values of one moment), or
        None when the time ran out."""
        end = time.monotonic() + timeout
        with self._cond:
            while True:
                if self._error is not None:
                    raise RuntimeError(f"the monitor's receiver failed: {self._error!r}") from self._error
                if predicate(self):
                    return self.snapshot()
                left = end - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(min(left, 0.1))

    def wait_state(self, state: str, timeout: float) -> Optional[dict]:
        """Wait until TCU_Status reports TcuState ``state`` (a name of its value table), at most
        ``timeout`` s: the snapshot at that frame, or None."""
        raw = choice("TCU_Status", "TcuState", state)
        return self.wait(lambda m: "TCU_Status" in m._latest and m._decoded("TCU_Status")["TcuState"] == raw, timeout)

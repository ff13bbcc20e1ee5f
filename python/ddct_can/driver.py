"""A scripted driver: DRV_Pedal (accelerator pedal, brake switch, gear lever) on the bus every
10 ms with the E2E alive counter and CRC of the contract.

    with Driver(bus) as driver:          # sends from a background thread: lever N, brake held
        driver.drive(brake=True)         # lever D, brake still held
        time.sleep(0.5)
        driver.pedal(50)                 # brake off, pedal 50 %

``launch(pct)`` performs the whole sequence the TCU needs (N, then D with the brake held, then
brake off and pedal). ``send()`` sends one frame (a lockstep bench answers each plant cycle with
it); ``play(seconds, program)`` plays a timeline on absolute 10 ms deadlines in the calling thread.

On a SocketCAN bus the background sender is the kernel's broadcast manager (CAN_BCM): one cyclic
task holding a frame per alive-counter value, its data replaced whenever the state changes. Its
10 ms come from a kernel timer, so a busy python process (a tester, a recorder, the GIL) cannot
stretch a gap into the TCU's 3-cycle input timeout. Other buses get a python thread.
"""

from __future__ import annotations

import threading
import time
from typing import Callable, Mapping, Optional

import can

from .dbc import frame_id, message
from .e2e import counter_modulus, encode

MESSAGE = "DRV_Pedal"
CYCLE_S = 0.01

# Neutral with the brake held: what the driver sends before anything else.
NEUTRAL = {"AccelPedal": 0.0, "BrakeSwitch": 1, "GearLever": "N"}

Program = Callable[[float], Mapping[str, object]]


class DriverError(RuntimeError):
    """The driver's sender thread failed (the cause is chained)."""


class Driver:
    """DRV_Pedal on ``bus`` (any python-can bus). The state starts as lever N with the brake held
    and no pedal; the sequence methods change it, the sender (``start()`` or the context manager)
    sends it every ``cycle_s`` on absolute deadlines with consecutive alive counters.

    ``sent`` counts the frames the bus accepted, ``dropped`` those it refused (a full transmit
    queue: the receiver's E2E check then sees a skipped counter, as on a real bus)."""

    def __init__(self, bus: can.BusABC, cycle_s: float = CYCLE_S, counter: int = 0,
                 kernel_timer: Optional[bool] = None):
        """``kernel_timer``: send from the kernel's broadcast manager (default: on SocketCAN buses)."""
        self.bus = bus
        self.kernel_timer = _is_socketcan(bus) if kernel_timer is None else kernel_timer
        self._task: Optional[can.broadcastmanager.ModifiableCyclicTaskABC] = None
        self._task_started = 0.0
        self.cycle_s = cycle_s
        self.counter = counter
        self.sent = 0
        self.dropped = 0
        self._fid = frame_id(MESSAGE)
        self._signals = {s.name for s in message(MESSAGE).signals}
        self._state = dict(NEUTRAL)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._error: Optional[BaseException] = None

    # -- state -----------------------------------------------------------------------------

    @property
    def state(self) -> dict:
        """The signals the next frame carries (physical values, the lever as its name)."""
        with self._lock:
            return dict(self._state)

    def set(self, **signals) -> None:
        """Set DRV_Pedal signals by name (AccelPedal %, BrakeSwitch 0/1, GearLever P/R/N/D)."""
        unknown = set(signals) - self._signals
        if unknown:
            raise KeyError(f"{MESSAGE} has no signal {sorted(unknown)} (it has {sorted(self._signals)})")
        encode(MESSAGE, {**self.state, **signals})  # range and choice check now, not in the thread
        with self._lock:
            self._state.update(signals)
            if self._task is not None:
                self._task.modify_data(self._counter_cycle())

    def neutral(self) -> None:
        """Lever N, brake held, no pedal."""
        self.set(GearLever="N", BrakeSwitch=1, AccelPedal=0.0)

    def park(self) -> None:
        self.set(GearLever="P", BrakeSwitch=1, AccelPedal=0.0)

    def drive(self, brake: bool = True) -> None:
        """Lever D, no pedal; the brake held (the TCU wants it for N -> D) unless ``brake=False``."""
        self.set(GearLever="D", BrakeSwitch=int(brake), AccelPedal=0.0)

    def reverse(self, brake: bool = True) -> None:
        self.set(GearLever="R", BrakeSwitch=int(brake), AccelPedal=0.0)

    def brake(self, on: bool = True) -> None:
        """Brake on (the pedal released) or off (the pedal as it was)."""
        if on:
            self.set(BrakeSwitch=1, AccelPedal=0.0)
        else:
            self.set(BrakeSwitch=0)

    def pedal(self, pct: float) -> None:
        """Brake off, accelerator pedal at ``pct`` %."""
        self.set(BrakeSwitch=0, AccelPedal=float(pct))

    def launch(self, pct: float, hold_s: float = 0.5) -> None:
        """The launch sequence: lever N with the brake held for ``hold_s``, lever D with the brake
        held for ``hold_s``, then brake off and the pedal at ``pct`` %. Needs the sender running
        (``start()`` or the context manager); returns once the pedal is pressed."""
        if not self.running:
            raise DriverError("launch() needs the sender running: start() the driver first")
        self.neutral()
        self._hold(hold_s)
        self.drive(brake=True)
        self._hold(hold_s)
        self.pedal(pct)

    def _hold(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while not self._stop.wait(max(0.0, min(0.05, end - time.monotonic()))):
            if time.monotonic() >= end:
                return
        self._raise_error()

    # -- sending ---------------------------------------------------------------------------

    def frame(self, signals: Optional[Mapping[str, object]] = None, counter: Optional[int] = None) -> can.Message:
        """The DRV_Pedal frame of ``signals`` (default: the current state) with ``counter``
        (default: the driver's next one)."""
        values = self.state if signals is None else dict(signals)
        data = encode(MESSAGE, values, counter=self.counter if counter is None else counter)
        return can.Message(arbitration_id=self._fid, data=data, is_extended_id=False)

    def send(self, signals: Optional[Mapping[str, object]] = None, counter: Optional[int] = None) -> bool:
        """Send one frame now. Without ``counter`` it carries the driver's counter, which then
        advances (also when the bus refuses the frame); with it (a second, spoofing node) the
        driver's counter is left alone. Returns whether the bus took the frame."""
        if counter is None and self._task is not None:
            raise DriverError("the kernel sends the driver's frames: send() with an explicit counter, or stop() first")
        msg = self.frame(signals, counter)
        if counter is None:
            self.counter += 1
        try:
            self.bus.send(msg)
        except can.CanError:
            self.dropped += 1
            return False
        self.sent += 1
        return True

    def play(self, seconds: float, program: Optional[Program] = None) -> int:
        """Send every ``cycle_s`` on absolute deadlines, in this thread, for ``seconds``: frame n
        at n·cycle_s carries ``program(n·cycle_s)`` (default: the current state). Returns the
        number of frames sent (including any the bus refused)."""
        start = time.monotonic()
        n = 0
        while not self._stop.is_set():
            t = n * self.cycle_s
            if t > seconds:
                break
            delay = start + t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            self.send(None if program is None else program(t))
            n += 1
        return n

    # -- the background sender -------------------------------------------------------------

    @property
    def running(self) -> bool:
        return self._task is not None or (self._thread is not None and self._thread.is_alive())

    def _counter_cycle(self) -> list:
        """One frame of the current state per alive-counter value, from the driver's counter on:
        the broadcast manager sends them in turn, so consecutive frames carry consecutive counters
        (also across a change of state, which replaces the data and keeps the kernel's index)."""
        state = dict(self._state)
        return [self.frame(state, self.counter + j) for j in range(counter_modulus(MESSAGE))]

    def start(self) -> "Driver":
        if self.running:
            raise DriverError("the driver is already running")
        self._stop.clear()
        self._error = None
        if self.kernel_timer:
            with self._lock:
                self._task = self.bus.send_periodic(self._counter_cycle(), self.cycle_s)
                self._task_started = time.monotonic()
            return self
        self._thread = threading.Thread(target=self._run, name="ddct-driver", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            self.play(float("inf"))
        except BaseException as e:  # noqa: BLE001 - reported by stop()
            self._error = e
            self._stop.set()

    def stop(self) -> None:
        """Stop the sender (within one cycle) and raise what made it fail, if anything did."""
        self._stop.set()
        if self._task is not None:
            with self._lock:
                task, self._task = self._task, None
                task.stop()
                # The kernel's place in the cycle is not readable: continue from the elapsed time.
                self.counter += round((time.monotonic() - self._task_started) / self.cycle_s)
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            if self._thread.is_alive():
                raise DriverError("the driver's sender thread did not stop within 5 s")
            self._thread = None
        self._raise_error()

    def _raise_error(self) -> None:
        if self._error is not None:
            err, self._error = self._error, None
            raise DriverError(f"the driver's sender failed: {err!r}") from err

    def __enter__(self) -> "Driver":
        return self.start()

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self.stop()
        except DriverError:
            if exc_type is None:
                raise


def _is_socketcan(bus: can.BusABC) -> bool:
    try:
        from can.interfaces.socketcan import SocketcanBus
    except ImportError:  # pragma: no cover - python-can always ships it
        return False
    return isinstance(bus, SocketcanBus)

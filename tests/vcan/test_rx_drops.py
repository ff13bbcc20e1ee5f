"""The python receivers tell their OWN drops from counters skipped on the bus (ddct_can.rx,
Monitor, E2EChecker), over vcan0 in the kernel.

A receiver with a tiny receive buffer (SO_RCVBUF) that reads slowly is flooded by canplayer (C,
as fast as the kernel takes the frames) with frames whose alive counters are all consecutive:
the kernel drops what the full queue cannot take and says so (SO_RXQ_OVFL); every frame is
either read or counted as dropped, the counter gaps those drops explain are local drops, and
there is no E2E error, since the bus carried no gap. A counter really skipped on the bus (a
frame left out by the sender, the receiver keeping up) is still an E2E error."""

from __future__ import annotations

import socket
import subprocess
import threading
import time

import can
import pytest

import ddct_can
import ddct_testlib as lib
from ddct_can import E2EChecker, Monitor, Receiver
from vcan_helpers import IFACE

FLOODED = ("ENG_Status", "DCT_Sensors")
N = 1500  # frames of each message in the flood


def payload(name: str, counter: int) -> bytes:
    signals = {"ENG_Status": {"EngSpeed": 1500.0, "EngTorqueAct": 40.0},
               "DCT_Sensors": {"InShaft1Speed": 1480.0, "InShaft2Speed": 900.0, "OutShaftSpeed": 400.0,
                               "HousingTemp": 60.0}}[name]
    return ddct_can.encode(name, signals, counter=counter)


def flood_log(tmp_path, first: int, n: int = N):
    """A candump log of FLOODED interleaved, counters first .. first+n-1 (mod 16)."""
    log = tmp_path / "flood.log"
    with open(log, "w") as f:
        for k in range(n):
            for name in FLOODED:
                f.write(ddct_can.candump_line(1.0 + k * 1e-4, IFACE, ddct_can.frame_id(name), payload(name, first + k)) + "\n")
    return log


def play(log) -> subprocess.Popen:
    """canplayer -t -g 0: the log's frames back to back, as fast as the kernel takes them."""
    return subprocess.Popen([lib.tool("canplayer", may_skip=True), "-t", "-g", "0", "-I", str(log)])


def flood(tmp_path, first: int, n: int = N) -> int:
    """Floods vcan0 (flood_log, play) and waits for the end; the frames sent."""
    log = flood_log(tmp_path, first, n)
    t0 = time.monotonic()
    assert play(log).wait(120) == 0
    print(f"flood: {n * len(FLOODED)} frames in {time.monotonic() - t0:.2f} s")
    return n * len(FLOODED)


def send(bus, name: str, counter: int, corrupt: bool = False) -> None:
    data = bytearray(payload(name, counter))
    if corrupt:
        data[7] ^= 0xFF
    bus.send(can.Message(arbitration_id=ddct_can.frame_id(name), data=bytes(data), is_extended_id=False))


def tiny_buffer(bus) -> int:
    bus.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1)  # the kernel's minimum
    return bus.socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)


class SlowMonitor(Monitor):
    """A monitor whose python falls behind (0.5 ms a frame) while ``slow`` is set."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.slow = threading.Event()

    def feed(self, *args, **kw):
        if self.slow.is_set():
            time.sleep(0.0005)
        super().feed(*args, **kw)


def test_a_flooded_monitor_reports_its_own_drops_not_e2e_errors(vcan0, tmp_path):
    with can.Bus(interface="socketcan", channel=IFACE) as tx, can.Bus(interface="socketcan", channel=IFACE) as rx:
        print(f"monitor's SO_RCVBUF: {tiny_buffer(rx)} bytes")
        mon = SlowMonitor(rx)
        assert mon.dropped == 0, "no drop counter on a SocketCAN socket"
        with mon:
            for name in FLOODED:  # each message's first frame, counter 0, read at leisure
                send(tx, name, 0)
            assert mon.wait(lambda m: all(m.frames[n] == 1 for n in FLOODED), timeout=10.0), dict(mon.frames)
            mon.slow.set()
            sent = 2 + flood(tmp_path, first=1)
            # Every frame is read or dropped by the kernel: the accounting is exact.
            done = mon.wait(lambda m: sum(m.frames[n] for n in FLOODED) + m.dropped == sent, timeout=60.0)
            read = sum(mon.frames[n] for n in FLOODED)
            assert done is not None, f"read {read} + dropped {mon.dropped} != sent {sent}"
            dropped, local = mon.dropped, dict(mon.local_drops)
            print(f"read {read}, dropped by the monitor's queue {dropped}, local-drop gaps {local}")
            assert dropped > 0, "the flood did not overflow the monitor's queue: nothing tested"
            assert sum(local.values()) > 0, local
            assert set(local) <= set(FLOODED), local
            assert not mon.e2e_errors, f"the monitor's own drops counted as bus errors: {dict(mon.e2e_errors)}"

            # Now the bus itself: the monitor keeps up; ENG_Status leaves out one counter, then a CRC.
            mon.slow.clear()
            c = N + 1
            before = mon.frames["ENG_Status"]

            def one(counter, corrupt=False):  # one frame, and the monitor has taken it
                n = mon.frames["ENG_Status"] + sum(mon.e2e_errors.values())
                send(tx, "ENG_Status", counter, corrupt)
                assert mon.wait(lambda m: m.frames["ENG_Status"] + sum(m.e2e_errors.values()) > n, timeout=10.0)

            for k in range(2):  # in sequence again (the flood's last frames may have been dropped)
                one(c + k)
            local = dict(mon.local_drops)
            assert not mon.e2e_errors, dict(mon.e2e_errors)
            one(c + 3)  # c + 2 never sent: a counter skipped on the bus
            one(c + 4, corrupt=True)
            one(c + 5)  # c + 4 did not count: skipped again
            assert mon.frames["ENG_Status"] == before + 4, dict(mon.frames)
        assert mon.dropped == dropped, "the monitor dropped frames while it kept up"
    assert dict(mon.e2e_errors) == {("ENG_Status", "counter_skipped"): 2, ("ENG_Status", "bad_crc"): 1}
    assert dict(mon.local_drops) == local


def test_a_flooded_receiver_and_checker_read_their_drops_per_frame(vcan0, tmp_path):
    """ddct_can.Receiver + E2EChecker, the parts the monitor is made of, in the caller's thread:
    the reader sleeps 1 ms a frame while canplayer floods, so its queue overflows; then it
    drains the queue, and then a counter skipped on the bus is still an E2E error."""
    with can.Bus(interface="socketcan", channel=IFACE) as tx, can.Bus(interface="socketcan", channel=IFACE) as bus:
        rx = Receiver(bus, rcvbuf=1)
        chk = E2EChecker()
        for name in FLOODED:
            send(tx, name, 0)
        verdicts: dict[str, int] = {}
        read = 0

        def drain(slow: bool, first_timeout: float = 0.5) -> None:
            nonlocal read
            timeout = first_timeout
            while (got := rx.recv_frame(timeout)) is not None:
                timeout = 0.5
                fid, data, ext, ts = got
                assert not ext and ts > 0
                v = chk.check(fid, data, lost=rx.lost)
                verdicts[v] = verdicts.get(v, 0) + 1
                read += 1
                if slow:
                    time.sleep(0.001)  # the reader falls behind: the queue overflows

        drain(slow=False)
        assert (read, verdicts) == (2, {"ok": 2})
        player = play(flood_log(tmp_path, first=1))
        drain(slow=True, first_timeout=30.0)
        assert player.wait(60) == 0
        drain(slow=False)
        sent = 2 + N * len(FLOODED)
        print(f"read {read}, dropped {rx.dropped_now()}, verdicts {verdicts}")
        assert rx.dropped > 0 and read + rx.dropped_now() == sent, (read, rx.dropped, rx.dropped_now(), sent)
        assert set(verdicts) <= {"ok", "local_drop"} and verdicts.get("local_drop", 0) > 0, verdicts
        # A gap on the bus with the reader keeping up: an E2E error, not a local drop.
        for k, c in enumerate((N + 1, N + 2, N + 4)):
            send(tx, "ENG_Status", c)
            got = rx.recv_frame(5.0)
            assert got is not None
            v = chk.check(got[0], got[1], lost=rx.lost)
            if k == 2:
                assert v == "counter_skipped", v
            elif k == 1:
                assert v == "ok", v

"""The receivers' own losses apart from the bus's, without kernel CAN: python-can's virtual bus
(which cannot say what a receiver lost: every gap is the bus's) and Monitor.feed with the
receiver's drop count. The kernel's drop counter itself is exercised over vcan0 in
tests/vcan/test_rx_drops.py."""

from __future__ import annotations

import uuid

import can
import pytest

import ddct_can
from ddct_can import Monitor, Receiver

ENG = ddct_can.frame_id("ENG_Status")


def eng(counter):
    return ddct_can.encode("ENG_Status", {"EngSpeed": 900.0, "EngTorqueAct": 5.0}, counter=counter)


@pytest.fixture
def buses():
    channel = f"ddct-rx-{uuid.uuid4()}"
    with can.Bus(interface="virtual", channel=channel) as tx, can.Bus(interface="virtual", channel=channel) as rx:
        yield tx, rx


def test_a_receiver_on_a_bus_without_a_drop_counter(buses):
    tx, rx_bus = buses
    rx = Receiver(rx_bus)
    assert rx.socket is None and rx.dropped is None and rx.lost is None and not rx.counts_drops
    tx.send(can.Message(arbitration_id=ENG, data=eng(4), is_extended_id=False))
    tx.send(can.Message(arbitration_id=0x004, is_extended_id=False, is_error_frame=True))
    tx.send(can.Message(arbitration_id=0x1ABCDEF, data=b"\x01", is_extended_id=True))
    fid, data, ext, _ = rx.recv_frame(1.0)
    assert (fid, data, ext) == (ENG, eng(4), False)
    msg = rx.recv(1.0)  # the error frame is skipped
    assert (msg.arbitration_id, msg.is_extended_id, bytes(msg.data)) == (0x1ABCDEF, True, b"\x01")
    assert rx.recv(0.05) is None and rx.recv_frame(0.0) is None


def test_monitor_without_a_drop_counter_counts_every_gap_as_the_buss(buses):
    tx, rx = buses
    with Monitor(rx) as mon:
        for c in (0, 1, 3):
            tx.send(can.Message(arbitration_id=ENG, data=eng(c), is_extended_id=False))
        assert mon.wait(lambda m: m.frames["ENG_Status"] == 3, timeout=2.0)
    assert mon.dropped is None
    assert dict(mon.e2e_errors) == {("ENG_Status", "counter_skipped"): 1}
    assert not mon.local_drops


def test_monitor_feed_puts_gaps_its_own_drops_explain_apart():
    mon = Monitor(can.Bus(interface="virtual", channel=f"ddct-rx-{uuid.uuid4()}"))
    try:
        mon.feed(ENG, eng(0), lost=0)
        mon.feed(ENG, eng(4), lost=3)  # 3 missing, 3 dropped by the monitor: its own
        mon.feed(ENG, eng(6), lost=3)  # 1 missing, none dropped: the bus's
        mon.feed(ENG, eng(7), lost=3)
        assert mon.frames["ENG_Status"] == 4
        assert dict(mon.local_drops) == {"ENG_Status": 1}
        assert dict(mon.e2e_errors) == {("ENG_Status", "counter_skipped"): 1}
        assert mon["ENG_Status"]["AliveCounter"] == 7
    finally:
        mon.bus.shutdown()

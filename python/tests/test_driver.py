"""Driver and Monitor on python-can's `virtual` interface (no kernel CAN needed): the frames'
signals, alive counters, CRCs and timing, checked by decoding them independently."""

from __future__ import annotations

import time
import uuid

import can
import pytest

import ddct_can
from ddct_can import Driver, Monitor

PEDAL = ddct_can.frame_id("DRV_Pedal")


@pytest.fixture
def buses():
    channel = f"ddct-test-{uuid.uuid4()}"
    tx = can.Bus(interface="virtual", channel=channel)
    rx = can.Bus(interface="virtual", channel=channel)
    yield tx, rx
    tx.shutdown()
    rx.shutdown()


def drain(bus, timeout=0.2):
    out = []
    while True:
        m = bus.recv(timeout=timeout)
        if m is None:
            return out
        out.append(m)


def lever(raw):
    return ddct_can.label("DRV_Pedal", "GearLever", raw)


def test_launch_sequence_frames(buses):
    tx, rx = buses
    t0 = time.monotonic()
    with Driver(tx) as driver:
        driver.launch(40.0, hold_s=0.3)
        time.sleep(0.3)
    elapsed = time.monotonic() - t0
    frames = drain(rx)
    assert frames, "the driver sent nothing"
    assert all(f.arbitration_id == PEDAL and not f.is_extended_id and len(f.data) == 8 for f in frames)
    # Every frame E2E-correct with consecutive counters (mod 16) from 0.
    chk = ddct_can.E2EChecker()
    assert [chk.check(PEDAL, bytes(f.data)) for f in frames] == ["ok"] * len(frames)
    assert [ddct_can.counter_of(PEDAL, bytes(f.data)) for f in frames] == [k % 16 for k in range(len(frames))]
    # 10 ms cycle: about elapsed / 10 ms frames (a loaded host may lag a few).
    assert 0.8 * elapsed / 0.01 <= len(frames) <= elapsed / 0.01 + 2, (len(frames), elapsed)
    # The phases, in order: N + brake, D + brake, D + pedal 40 % without brake.
    sig = [ddct_can.decode(PEDAL, bytes(f.data)) for f in frames]
    phases = []
    for s in sig:
        key = (lever(s["GearLever"]), s["BrakeSwitch"], round(s["AccelPedal"], 1))
        if not phases or phases[-1][0] != key:
            phases.append([key, 0])
        phases[-1][1] += 1
    assert [p[0] for p in phases] == [("N", 1, 0.0), ("D", 1, 0.0), ("D", 0, 40.0)], phases
    assert all(n >= 20 for _, n in phases), phases  # each phase held ~0.3 s = ~30 cycles
    assert driver.sent == len(frames) and driver.dropped == 0


def test_send_with_explicit_counter_leaves_the_drivers_counter(buses):
    tx, rx = buses
    d = Driver(tx)
    d.send()
    d.send({"AccelPedal": 100.0, "BrakeSwitch": 0, "GearLever": "R"}, counter=9)
    d.send()
    frames = drain(rx)
    assert [ddct_can.counter_of(PEDAL, bytes(f.data)) for f in frames] == [0, 9, 1]
    assert lever(ddct_can.decode(PEDAL, bytes(frames[1].data))["GearLever"]) == "R"
    assert [ddct_can.check(PEDAL, bytes(f.data)) for f in frames] == ["ok"] * 3


def test_play_follows_a_program_on_the_cycle(buses):
    tx, rx = buses
    d = Driver(tx)
    n = d.play(0.2, lambda t: {"AccelPedal": 0.0 if t < 0.1 else 20.0, "BrakeSwitch": 0, "GearLever": "D"})
    frames = drain(rx)
    assert n == len(frames) == 21  # t = 0, 10, ..., 200 ms
    pedals = [round(ddct_can.decode(PEDAL, bytes(f.data))["AccelPedal"], 1) for f in frames]
    assert pedals == [0.0] * 10 + [20.0] * 11


def test_bad_values_fail_in_the_caller_not_the_thread(buses):
    tx, _ = buses
    d = Driver(tx)
    with pytest.raises(KeyError):
        d.set(Throttle=3)
    with pytest.raises(Exception):
        d.pedal(150.0)  # outside [0, 100]
    with pytest.raises(Exception):
        d.set(GearLever="X")
    assert d.state == {"AccelPedal": 0.0, "BrakeSwitch": 1, "GearLever": "N"}


def test_launch_needs_the_sender(buses):
    with pytest.raises(ddct_can.DriverError):
        Driver(buses[0]).launch(30)


def test_stop_reports_a_failed_sender():
    class Broken(can.BusABC):
        def __init__(self):
            super().__init__(channel="broken")

        def send(self, msg, timeout=None):
            raise OSError("bus gone")

        def _recv_internal(self, timeout):
            return None, False

    d = Driver(Broken()).start()
    time.sleep(0.05)
    with pytest.raises(ddct_can.DriverError, match="bus gone"):
        d.stop()


def test_monitor_decodes_checks_and_waits(buses):
    tx, rx = buses
    status = ddct_can.frame_id("TCU_Status")
    with Monitor(rx) as mon:
        assert mon.tcu_state() is None
        for c, state in enumerate(["Neutral", "Launch", "Drive"]):
            data = ddct_can.encode("TCU_Status", {"GearActive": 1, "TcuState": state, "FaultCode": 0}, counter=c)
            tx.send(can.Message(arbitration_id=status, data=data, is_extended_id=False))
        assert mon.wait_state("Drive", timeout=2.0)
        assert mon.tcu_state() == "Drive"
        bad = bytearray(ddct_can.encode("TCU_Status", {"GearActive": 1, "TcuState": "SafeState", "FaultCode": 0}, counter=3))
        bad[7] ^= 0xFF
        tx.send(can.Message(arbitration_id=status, data=bytes(bad), is_extended_id=False))
        assert mon.wait(lambda m: m.e2e_errors, timeout=2.0)
        assert not mon.wait_state("SafeState", timeout=0.2)  # the bad frame was not taken
    assert mon.frames["TCU_Status"] == 3
    assert dict(mon.e2e_errors) == {("TCU_Status", "bad_crc"): 1}


def test_monitor_with_messages_filters_the_rest(buses):
    tx, rx = buses
    eng = ddct_can.encode("ENG_Status", {"EngSpeed": 1000.0, "EngTorqueAct": 0.0}, counter=0)
    temps = ddct_can.encode("BENCH_Temps", {"PressurePlate1Temp": 80.0, "PressurePlate2Temp": 80.0, "CentralDiskTemp": 80.0})
    with Monitor(rx, ["ENG_Status"]) as mon:
        for name, data in (("BENCH_Temps", temps), ("ENG_Status", eng)):
            tx.send(can.Message(arbitration_id=ddct_can.frame_id(name), data=data, is_extended_id=False))
        seen = mon.wait(lambda m: m.frames["ENG_Status"] == 1, timeout=2.0)
    assert seen == {"ENG_Status": {"EngSpeed": 1000.0, "EngTorqueAct": 0.0, "AliveCounter": 0, "Crc": eng[7]}}
    assert "BENCH_Temps" not in mon.frames

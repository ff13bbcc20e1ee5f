"""scripts/launch.py's analysis of a lockstep log in bus time, on hand-built frame sequences whose
expected times and fault timing are worked out here by hand (the plant's cycle order: ENG_Status,
DCT_Sensors, DCT_Actuators, then the TCU's five frames and the driver's DRV_Pedal)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))

import launch as hil  # noqa: E402

from ddct_testlib import ddct_can  # noqa: E402


def rec(name, data=b"\0" * 8, t=0.0):
    return (t, "vcan0", hil.frame_id(name), False, bytes(data))


def cycle(n, status=None, eng=True):
    """One lockstep cycle's frames (wall times made up and out of step on purpose)."""
    out = []
    if eng:
        out.append(rec("ENG_Status", t=1000.0 + 0.37 * n))
    out += [rec("DCT_Sensors", t=1000.0 + 0.37 * n), rec("DCT_Actuators", t=1000.0 + 0.37 * n)]
    if status is not None:
        out.append(rec("TCU_Status", status, t=1000.0 + 0.37 * n + 0.2))
    out.append(rec("DRV_Pedal", t=1000.0 + 0.37 * n + 0.3))
    return out


def test_bus_time_puts_every_frame_on_its_plant_cycle():
    recs = cycle(0) + cycle(1) + cycle(2)
    times = [(t, fid) for t, _, fid, _, _ in hil.bus_time(recs)]
    eng, sens = hil.frame_id("ENG_Status"), hil.frame_id("DCT_Sensors")
    assert [t for t, f in times if f == eng] == [0.0, 0.01, 0.02]
    assert [t for t, f in times if f == sens] == [0.0, 0.01, 0.02]
    # Every frame carries its cycle's time, whatever the wall clock said.
    assert [round(t, 6) for t, _ in times] == [0.0] * 4 + [0.01] * 4 + [0.02] * 4


def status(state, fault, counter):
    return ddct_can.encode(
        "TCU_Status", {"GearActive": 1, "TcuState": state, "FaultCode": fault}, counter=counter
    )


def test_fault_timing_of_a_stopped_message_in_bus_time():
    drive = hil.choice("TCU_Status", "TcuState", "Drive")
    safe = hil.choice("TCU_Status", "TcuState", "SafeState")
    code = hil.choice("TCU_Status", "FaultCode", "EngStatusTimeout")
    recs = []
    for n in range(20):
        # ENG_Status stopped in cycles 5..9; the TCU flags it in cycle 8 (4 cycles after the last
        # valid frame, cycle 4) and is back in Drive in cycle 11 (1 after the first valid, 10).
        eng = {"EngSpeed": 1000.0, "EngTorqueAct": 0.0}
        down = 8 <= n <= 10
        st = status(safe if down else drive, code if down else 0, n)
        c = cycle(n, st, eng=not (5 <= n <= 9))
        if not (5 <= n <= 9):
            c[0] = rec("ENG_Status", ddct_can.encode("ENG_Status", eng, counter=n))
        recs += c
    ft = hil.fault_timing(hil.bus_time(recs), "ENG_Status", "EngStatusTimeout", 0.05, 0.0)
    assert round(ft["detection_ms"], 6) == 40.0
    assert round(ft["safe_state_after_detection_ms"], 6) == 0.0
    assert round(ft["recovery_ms"], 6) == 10.0

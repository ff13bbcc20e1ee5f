"""The plant and TCU daemons over vcan0 (kernel SocketCAN, host or User-Mode Linux), the driver
played from python, everything recorded by `ddct log record` with kernel timestamps.

Timing over vcan is measured and printed, and asserted only with generous bounds: under
User-Mode Linux the whole guest shares one virtual CPU with the host's other work, and its timing
tail is noisy (DESIGN.md §7). The exact timing properties (detection within 3 cycles, safe state
in the next cycle, recovery within 100 ms) are asserted in simulated time by tests/tcu.rs.
"""

from __future__ import annotations

import json

import launch as hil
import pytest

# Generous bounds for a noisy bus (the in-process bus asserts 30 ms / 10 ms / 100 ms exactly).
DETECT_MAX_MS = 250.0
RECOVER_MAX_MS = 1500.0


def show(name, a, run):
    print(f"\n== {name}")
    hil.print_table(a, run)


def disturbed(a, driving_s):
    """A safe state while the driver still drives: the host stalled a sender (User-Mode Linux
    shares one virtual CPU with the host's other work), so this run cannot time the launch."""
    return any(e["state"] == "SafeState" and e["t"] < driving_s - 0.5 for e in a["events"])


def launch_run(ddct, out_dir, attempt):
    run = hil.run_bench(program="launch", pedal=50.0, seconds=6.0, out=out_dir, ddct=ddct, name=f"launch50_{attempt}")
    a = hil.analyse(run.records, hil.target_rpm(50.0))
    show(f"launch 50 % (attempt {attempt})", a, run)
    return a


def test_launch_at_half_pedal_locks_up_and_drives(ddct, out_dir):
    a = launch_run(ddct, out_dir, 1)
    la = a["launch"]
    launch_ok = (
        la is not None
        and la["lockup_s"] is not None
        and la["lockup_s"] < 4.0
        and la["min_engine_rpm"] > 500.0
        and "Drive" in {e["state"] for e in a["events"]}
    )
    if not launch_ok and disturbed(a, 6.0):
        print("the host disturbed the run with a sender timeout: once more")
        a = launch_run(ddct, out_dir, 2)
        la = a["launch"]
    assert la is not None, "no launch seen on the bus"
    assert la["lockup_s"] is not None and la["lockup_s"] < 4.0, la
    assert la["min_engine_rpm"] > 500.0, la
    states = {e["state"] for e in a["events"]}
    assert "Drive" in states, a["events"]
    assert a["latency_us"]["n"] > 100


def shifts_run(ddct, out_dir, attempt):
    run = hil.run_bench(program="shifts", pedal=50.0, seconds=15.0, out=out_dir, ddct=ddct, name=f"shifts50_{attempt}")
    a = hil.analyse(run.records, hil.target_rpm(50.0))
    show(f"launch and upshifts at 50 % (attempt {attempt})", a, run)
    ups = [(s["from"], s["to"]) for s in a["shifts"] if s["up"] and s["completed"]]
    gears = {r.get("TCU_Status.GearActive") for r in hil.rows_of(run.records)}
    return a, ups, gears, disturbed(a, 15.0)


def test_upshifts_at_half_pedal(ddct, out_dir):
    a, ups, gears, was_disturbed = shifts_run(ddct, out_dir, 1)
    if ((1, 2) not in ups or 3 not in gears) and was_disturbed:
        print("the host disturbed the run with a sender timeout: once more")
        a, ups, gears, _ = shifts_run(ddct, out_dir, 2)
    assert (1, 2) in ups, a["shifts"]
    # Third gear is reached (a timing hiccup of the host may interrupt one shift with a safe
    # state; the TCU then re-engages the gear the schedule wants).
    assert 3 in gears, a["shifts"]


FAULTS = [
    ("ENG_Status", "stop", "EngStatusTimeout"),
    ("ENG_Status", "corrupt_crc", "EngStatusCrc"),
    ("ENG_Status", "freeze_counter", "EngStatusCounter"),
]


def fault_case(ddct, out_dir, message, kind, expected, attempt):
    f_from, f_to = 3.5, 4.0
    faults = out_dir / f"faults_{attempt}.toml"
    faults.write_text(f'[[faults]]\nmessage = "{message}"\nkind = "{kind}"\nfrom_s = {f_from}\nto_s = {f_to}\n')
    run = hil.run_bench(
        program="launch", pedal=40.0, seconds=6.0, out=out_dir, ddct=ddct, faults=faults, name=f"fault_{kind}_{attempt}"
    )
    sensors = hil.frame_id("DCT_Sensors")
    t_plant0 = next(t for t, _, i, _, _ in run.records if i == sensors)
    ft = hil.fault_timing(run.records, message, expected, f_from, t_plant0)
    a = hil.analyse(run.records, hil.target_rpm(40.0))
    show(f"{kind} on {message} in [{f_from}, {f_to}) s (attempt {attempt})", a, run)
    print("fault timing over vcan:", json.dumps(ft))
    # A fault code before the injection started: the host stalled the bus (a timing hiccup of
    # User-Mode Linux), so this run cannot time the injected fault.
    t_inj = f_from + (t_plant0 - run.records[0][0])
    disturbed = any(e["fault"] != "None" and e["state"] != "Init" and e["t"] < t_inj for e in a["events"])
    return a, ft, disturbed


@pytest.mark.parametrize("message,kind,expected", FAULTS)
def test_faults_are_detected_and_recovered(ddct, out_dir, message, kind, expected):
    a, ft, disturbed = fault_case(ddct, out_dir, message, kind, expected, 1)
    ok = ft["detection_ms"] is not None and 0.0 < ft["detection_ms"] <= DETECT_MAX_MS
    if not ok and disturbed:
        print("the host disturbed the run before the injection: once more")
        a, ft, disturbed = fault_case(ddct, out_dir, message, kind, expected, 2)
    codes = {e["fault"] for e in a["events"]}
    assert expected in codes, a["events"]
    assert ft["detection_ms"] is not None and 0.0 < ft["detection_ms"] <= DETECT_MAX_MS, ft
    assert ft["safe_state_after_detection_ms"] is not None and ft["safe_state_after_detection_ms"] <= DETECT_MAX_MS, ft
    assert ft["recovery_ms"] is not None and 0.0 < ft["recovery_ms"] <= RECOVER_MAX_MS, ft

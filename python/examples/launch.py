"""A launch over vcan0 against ddct's plant and TCU daemons; the clutch must lock up.
Needs vcan0 up (scripts/vcan-run brings it up); runs from any directory, e.g. in the checkout:
    scripts/vcan-run .venv/bin/python python/examples/launch.py
ddct: $DDCT_BIN, else ddct on PATH, else the checkout's target/release/ddct (built-in calibration)."""
import can
from ddct_can import Bench, Driver, Monitor

with can.Bus(interface="socketcan", channel="vcan0") as bus, Driver(bus) as driver, \
        Monitor(bus) as mon, Bench("vcan0"):
    driver.launch(50)  # lever N, then D with the brake held, then brake off and 50 % pedal
    assert mon.wait_state("Launch", timeout=2.0), f"no launch: the TCU is in {mon.tcu_state()}"
    seen = mon.wait_state("Drive", timeout=15.0)  # Launch -> Drive: the TCU saw lock-up
    assert seen, f"no lock-up: the TCU is in {mon.tcu_state()}"
    slip = seen["ENG_Status"]["EngSpeed"] - seen["DCT_Sensors"]["InShaft1Speed"]
    assert abs(slip) < 20.0, f"Drive with {slip:.1f} rpm of clutch slip"  # frames a cycle apart
    assert not mon.e2e_errors, f"E2E errors on the bus: {dict(mon.e2e_errors)}"  # not the monitor's own drops
print(f"locked up: clutch slip {slip:+.1f} rpm")

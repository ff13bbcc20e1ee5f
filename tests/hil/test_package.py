"""The ddct_can package (python/) over vcan0 as its documentation shows it: the README's example,
run as it is from a directory outside the checkout, and the pytest fixtures the package brings
(ddct_bench, ddct_driver, ddct_monitor) with their defaults: the whole-bus monitor, the binary's
built-in calibration.

DDCT_PACKAGE_RUNS=N runs the fixtures' test N times (default 1), e.g. 20 in one boot:
    cd /tmp && /work/main/scripts/vcan-run env DDCT_PACKAGE_RUNS=20 \\
        /work/main/.venv/bin/python -m pytest /work/main/tests/hil/test_package.py -k fixtures
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import ddct_can

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "python" / "examples" / "launch.py"
RUNS = int(os.environ.get("DDCT_PACKAGE_RUNS", "1"))


def test_readme_example_drives_a_launch_to_lock_up_from_any_directory(ddct, tmp_path):
    """From an empty directory; the binary through DDCT_BIN, or, when it is this checkout's own
    build and no ddct is on PATH, found by the package itself (no variable)."""
    env = dict(os.environ)
    if Path(ddct).resolve() == (REPO / "target" / "release" / "ddct").resolve() and not shutil.which("ddct"):
        env.pop("DDCT_BIN", None)
    else:
        env["DDCT_BIN"] = str(ddct)
    proc = subprocess.run([sys.executable, str(EXAMPLE)], cwd=tmp_path, env=env,
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120)
    print(proc.stdout, proc.stderr)
    assert proc.returncode == 0, f"python/examples/launch.py exited {proc.returncode}:\n{proc.stderr[-3000:]}"
    m = re.fullmatch(r"locked up: clutch slip ([+-]\d+\.\d) rpm\n", proc.stdout)
    assert m and abs(float(m.group(1))) < 20.0, proc.stdout
    assert list(tmp_path.iterdir()) == [], "the example left files in its working directory"


@pytest.mark.parametrize("run", range(RUNS))
def test_fixtures_launch_lock_up_and_upshift(ddct_bench, ddct_driver, ddct_monitor, run):
    """The daemons from ddct_bench, the driver and the whole-bus monitor (the default) on the bus
    before them: a launch at 30 % pedal to lock-up in first gear, then the upshift to second;
    no E2E error on the bus (the monitor's own drops, if the guest starves it, are counted
    apart and are not errors of the bus)."""
    mon = ddct_monitor
    gear = lambda m: ddct_can.label("TCU_Status", "GearActive", m["TCU_Status"]["GearActive"])  # noqa: E731
    ddct_driver.launch(30.0)
    assert mon.wait_state("Launch", timeout=2.0), mon.tcu_state()
    seen = mon.wait_state("Drive", timeout=15.0)  # generous: a starved real-time guest
    assert seen, f"no lock-up at 30 % pedal: the TCU is in {mon.tcu_state()}"
    slip = seen["ENG_Status"]["EngSpeed"] - seen["DCT_Sensors"]["InShaft1Speed"]
    assert abs(slip) < 20.0, slip  # ENG_Status and DCT_Sensors may be one 10 ms cycle apart
    assert gear(seen) == "G1", seen["TCU_Status"]
    assert mon.wait_state("Upshift", timeout=20.0), f"no upshift: the TCU is in {mon.tcu_state()}"
    up = mon.wait(lambda m: m.tcu_state() == "Drive" and gear(m) == "G2", timeout=10.0)
    assert up, f"the upshift did not end in second gear: {mon.tcu_state()}, {mon.get('TCU_Status')}"
    slip2 = up["ENG_Status"]["EngSpeed"] - up["DCT_Sensors"]["InShaft2Speed"]
    ddct_bench.check_running()
    ddct_bench.stop()  # SIGTERM; raises unless both exit with status 0 and their reports
    assert ddct_bench.tcu_report["stopped_by"] == "shutdown", ddct_bench.tcu_report
    print(f"\nrun {run}: lock-up slip {slip:+.1f} rpm, G2 at {up['BENCH_Vehicle']['VehicleSpeed']:.1f} km/h "
          f"(slip {slip2:+.1f} rpm); monitor: {sum(mon.frames.values())} frames, own drops {mon.dropped} "
          f"(counter gaps they explain: {dict(mon.local_drops)})")
    assert mon.dropped is not None, "the monitor has no drop counter on SocketCAN"
    assert not mon.e2e_errors, f"E2E errors on the bus: {dict(mon.e2e_errors)}"
    assert mon.frames["TCU_Status"] > 0 and mon.frames["SIM_Truth"] > 0, dict(mon.frames)  # the whole bus

"""The ddct_can package (python/) over vcan0: the README's example, run as it is, and the pytest
fixtures the package brings (ddct_bench, ddct_driver, ddct_monitor)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import ddct_can

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "python" / "examples" / "launch.py"


def test_readme_example_drives_a_launch_to_lock_up(ddct):
    proc = subprocess.run([sys.executable, str(EXAMPLE)], cwd=REPO, env={**os.environ, "DDCT_BIN": str(ddct)},
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120)
    print(proc.stdout, proc.stderr)
    assert proc.returncode == 0, f"python/examples/launch.py exited {proc.returncode}:\n{proc.stderr[-3000:]}"
    m = re.fullmatch(r"locked up: clutch slip ([+-]\d+\.\d) rpm\n", proc.stdout)
    assert m and abs(float(m.group(1))) < 20.0, proc.stdout


@pytest.mark.ddct_monitor(messages=["TCU_Status", "ENG_Status", "DCT_Sensors"])
def test_fixtures_launch_and_lock_up(ddct_bench, ddct_driver, ddct_monitor):
    """The daemons from ddct_bench, the driver and the monitor on the bus before them. The
    monitor watches the three messages the check reads: decoding the whole bus in python starved
    the daemons of the single-CPU guest (fresh-clone CI: still in Launch after 8 s)."""
    ddct_driver.launch(30.0)
    assert ddct_monitor.wait_state("Launch", timeout=2.0), ddct_monitor.tcu_state()
    seen = ddct_monitor.wait_state("Drive", timeout=15.0)  # generous: a starved real-time guest
    assert seen, f"no lock-up at 30 % pedal: the TCU is in {ddct_monitor.tcu_state()}"
    slip = seen["ENG_Status"]["EngSpeed"] - seen["DCT_Sensors"]["InShaft1Speed"]
    assert abs(slip) < 20.0, slip  # ENG_Status and DCT_Sensors may be one 10 ms cycle apart
    assert seen["TCU_Status"]["GearActive"] == ddct_can.choice("TCU_Status", "GearActive", "G1")
    ddct_bench.check_running()
    ddct_bench.stop()  # SIGTERM; raises unless both exit with status 0 and their reports
    assert ddct_bench.tcu_report["stopped_by"] == "shutdown", ddct_bench.tcu_report

"""`pip install ./python` into a fresh virtual environment: the package, its DBC and its pytest
entry point are there and work, imported from the environment (not from this source tree).

Needs the package index (pip fetches setuptools for the build, python-can and cantools) or a
configured mirror; without it the test fails with pip's output."""

from __future__ import annotations

import shutil
import subprocess
import sys
import venv
from pathlib import Path

PROJECT = Path(__file__).resolve().parents[1]

PROBE = """
import importlib.metadata as md, sys, ddct_can
from pathlib import Path
assert Path(ddct_can.__file__).resolve().is_relative_to(Path(sys.prefix).resolve()), ddct_can.__file__
assert ddct_can.DBC_PATH.is_file()
data = ddct_can.encode("DRV_Pedal", {"AccelPedal": 50.0, "BrakeSwitch": 0, "GearLever": "D"}, counter=3)
assert ddct_can.check(ddct_can.frame_id("DRV_Pedal"), data) == "ok", data.hex()
eps = [e.value for e in md.entry_points(group="pytest11") if e.name == "ddct_can"]
assert eps == ["ddct_can.pytest_plugin"], eps
print("ok", ddct_can.__file__, data.hex(), md.version("python-can"), md.version("cantools"))
"""


def test_pip_install_into_a_fresh_venv(tmp_path):
    # A copy of python/: pip's in-tree build writes build/ and *.egg-info next to the sources.
    src = tmp_path / "src"
    shutil.copytree(PROJECT, src, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__", ".pytest_cache"))
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    py = env_dir / "bin" / "python"
    pip = subprocess.run([py, "-m", "pip", "install", "--disable-pip-version-check", "-q", str(src)],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert pip.returncode == 0, f"pip install ./python failed:\n{pip.stdout[-3000:]}\n{pip.stderr[-3000:]}"
    probe = subprocess.run([py, "-c", PROBE], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert probe.returncode == 0, probe.stderr
    assert probe.stdout.startswith("ok "), probe.stdout
    assert "f4190000000030ef" in probe.stdout  # the frame this package encodes in the source tree too
    assert sys.prefix not in probe.stdout.split()[1]

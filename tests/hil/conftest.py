"""Fixtures of the HIL suite: the plant and TCU daemons over vcan0 with the driver played from
python (scripts/launch.py, built on the ddct_can package in python/, whose pytest fixtures
ddct_bench, ddct_driver, ddct_monitor are available here too). Needs an up vcan0: run it through
scripts/vcan-run (which sets DDCT_REQUIRE_VCAN=1, so a missing vcan0 or binary fails instead of
skipping)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1] / "tests" / "python"))
sys.path.insert(0, str(HERE.parents[1] / "scripts"))

import ddct_testlib as lib  # noqa: E402

IFACE = "vcan0"


@pytest.fixture(scope="session")
def vcan0():
    return lib.require_vcan(IFACE)


@pytest.fixture(scope="session")
def ddct(vcan0):
    return lib.ddct_bin(may_skip=True)


# The package's fixtures (ddct_can.pytest_plugin) on the same interface and binary.
@pytest.fixture(scope="session")
def ddct_iface(vcan0):
    return vcan0


@pytest.fixture(scope="session")
def ddct_bin(ddct):
    return ddct


@pytest.fixture(scope="session", autouse=True)
def report_where():
    print(f"\nHIL suite: DDCT_VCAN={os.environ.get('DDCT_VCAN', '?')} kernel={os.environ.get('DDCT_VCAN_KERNEL', '?')}")
    yield


@pytest.fixture
def out_dir(tmp_path):
    return tmp_path

"""Fixtures of the HIL suite: the plant and TCU daemons over vcan0 with the driver played from
python (scripts/launch.py). Needs an up vcan0: run it through scripts/vcan-run (which sets
DDCT_REQUIRE_VCAN=1, so a missing vcan0 or binary fails instead of skipping)."""

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
ARPHRD_CAN = 280
IFF_UP = 0x1


@pytest.fixture(scope="session")
def vcan0():
    sysfs = Path("/sys/class/net") / IFACE
    if not sysfs.exists():
        lib.missing(f"{IFACE} does not exist", may_skip=True)
    if int((sysfs / "type").read_text()) != ARPHRD_CAN:
        lib.missing(f"{IFACE} is not a CAN interface", may_skip=True)
    if not int((sysfs / "flags").read_text(), 16) & IFF_UP:
        lib.missing(f"{IFACE} is down", may_skip=True)
    return IFACE


@pytest.fixture(scope="session")
def ddct(vcan0):
    return lib.ddct_bin(may_skip=True)


@pytest.fixture(scope="session", autouse=True)
def report_where():
    print(f"\nHIL suite: DDCT_VCAN={os.environ.get('DDCT_VCAN', '?')} kernel={os.environ.get('DDCT_VCAN_KERNEL', '?')}")
    yield


@pytest.fixture
def out_dir(tmp_path):
    return tmp_path

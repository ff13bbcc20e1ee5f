"""Fixtures of the vcan suites: they need an up vcan0 (scripts/vcan-run provides one).

Missing vcan0 or tools fail the tests when DDCT_REQUIRE_VCAN=1 (always so under scripts/vcan-run);
run by hand without it, they skip.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python"))

import ddct_testlib as lib  # noqa: E402
from vcan_helpers import IFACE  # noqa: E402



@pytest.fixture(scope="session")
def vcan0():
    return lib.require_vcan(IFACE)


@pytest.fixture(scope="session")
def ddct(vcan0):
    return lib.ddct_bin(may_skip=True)


@pytest.fixture(scope="session")
def candump(vcan0):
    return lib.tool("candump", may_skip=True)


@pytest.fixture(scope="session")
def cansend(vcan0):
    return lib.tool("cansend", may_skip=True)


@pytest.fixture(scope="session", autouse=True)
def report_where():
    where = os.environ.get("DDCT_VCAN", "?")
    kernel = os.environ.get("DDCT_VCAN_KERNEL", "?")
    print(f"\nvcan suite: DDCT_VCAN={where} kernel={kernel}")
    yield


@pytest.fixture(scope="session")
def db():
    return lib.ddct_can.load_dbc()

"""Fixtures of the diagnostic suite (issue 16): the plant and TCU daemons on vcan0 with the real
clients — udsoncan over can-isotp (user-space ISO-TP on python-can: the User-Mode Linux kernel
has no can-isotp module) and pyxcp. Run by scripts/test inside scripts/vcan-run; a missing vcan0
fails there (DDCT_REQUIRE_VCAN=1) and skips only when run by hand.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import ddct_testlib as lib  # noqa: E402

IFACE = "vcan0"


@pytest.fixture(scope="session")
def vcan0():
    return lib.require_vcan(IFACE)


@pytest.fixture(scope="session")
def ddct(vcan0):
    return lib.ddct_bin(may_skip=True)

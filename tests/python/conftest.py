"""Fixtures of the plain python suite: every tool a test needs must be there (no skips)."""

from __future__ import annotations

import pytest

import ddct_testlib as lib


@pytest.fixture(scope="session")
def ddct():
    return lib.ddct_bin()


@pytest.fixture(scope="session")
def db():
    return lib.ddct_can.load_dbc()


@pytest.fixture(scope="session")
def bench_launch_shift(ddct, tmp_path_factory):
    """`ddct bench --iface sim --echo 0` of the bench's scenario (launch_shift_20s, the binary's
    default) into a folder of its own, once for the session: (the folder, the run). The report
    page's test and the MF4 tests read the same run (20 s of real time each, before)."""
    out = tmp_path_factory.mktemp("bench_launch_shift") / "bench"
    r = lib.run([ddct, "bench", "--iface", "sim", "--echo", "0", "--scenario",
                 lib.REPO / "config" / "scenarios" / "launch_shift_20s.toml", "--out", out], check=False, timeout=300)
    return out, r

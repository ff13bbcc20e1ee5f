"""Helpers of the vcan suites: receivers registered on vcan0, background processes."""

from __future__ import annotations

import subprocess
import time
from contextlib import contextmanager

import ddct_can

IFACE = "vcan0"


def can_receivers(iface: str = IFACE) -> frozenset | None:
    """The kernel's CAN receive-list entries on iface (see ddct_can.can_receivers)."""
    return ddct_can.can_receivers(iface)


def wait_receivers(before: frozenset | None, added: int, procs=(), timeout: float = 30.0):
    """Wait until `added` receivers not in `before` are registered on vcan0, so that no frame
    is sent before a receiver started in the background listens."""
    deadline = time.monotonic() + timeout
    if before is None:  # no procfs: give the receivers time to start
        time.sleep(2.0)
        return
    while len(can_receivers() - before) < added:
        for p in procs:
            if p.poll() is not None:
                out, err = p.communicate()
                raise AssertionError(f"{p.args} exited {p.returncode} before it listened: {err or out}")
        if time.monotonic() > deadline:
            raise AssertionError(f"receivers did not register on {IFACE} within {timeout} s")
        time.sleep(0.05)


@contextmanager
def background(args, **kw):
    """A subprocess killed (if still running) when the block ends."""
    p = subprocess.Popen([str(a) for a in args], stdin=subprocess.DEVNULL, **kw)
    try:
        yield p
    finally:
        if p.poll() is None:
            p.terminate()
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

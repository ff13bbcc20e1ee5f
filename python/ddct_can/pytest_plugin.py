"""pytest fixtures for benches on ddct's CAN bus (registered through the ``pytest11`` entry point,
so installing the package makes them available to any test).

Fixtures:
    ddct_bin       the ddct binary (--ddct-bin, else $DDCT_BIN, else ddct on PATH, else the
                   target/release/ddct of the checkout an editable install of the package lives in)
    ddct_iface     the CAN interface (--ddct-iface, else $DDCT_IFACE, else vcan0); it must exist,
                   be a CAN interface and be up
    ddct_bus       a python-can socketcan bus on it
    ddct_monitor   a Monitor on ddct_bus, running; on the whole bus, or only on the messages a
                   test names with ``@pytest.mark.ddct_monitor(messages=[...])`` (kernel-filtered:
                   less work for a small machine). ``e2e_errors`` holds what the bus showed; the
                   frames the monitor itself lost when its python fell behind (a starved
                   single-CPU guest) are in ``dropped`` and ``local_drops``, not errors
    ddct_driver    a Driver on ddct_bus, sending (lever N, brake held)
    ddct_bench     the plant and TCU daemons (Bench), started after the monitor and the driver,
                   stopped and checked at teardown; the TCU's calibration is --ddct-tcu-config,
                   else the one built into the binary (config/tcu.toml of its source), so the
                   tests run the same from any directory

A missing binary or interface fails the test (it never skips).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ARPHRD_CAN = 280
IFF_UP = 0x1


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "ddct_monitor(messages): the messages the ddct_monitor fixture watches (default: all)"
    )


def pytest_addoption(parser):
    g = parser.getgroup("ddct_can", "ddct CAN bench")
    g.addoption("--ddct-bin", default=None,
                help="the ddct binary (default $DDCT_BIN, then ddct on PATH, then an editable checkout's target/release/ddct)")
    g.addoption("--ddct-iface", default=None, help="CAN interface of the bench (default $DDCT_IFACE or vcan0)")
    g.addoption("--ddct-tcu-config", default=None,
                help="the TCU's calibration file (default: the one built into the binary)")


def interface_problem(iface: str):
    """Why ``iface`` cannot carry a bench (None when it can)."""
    sysfs = Path("/sys/class/net") / iface
    if not sysfs.exists():
        return f"{iface} does not exist"
    if int((sysfs / "type").read_text()) != ARPHRD_CAN:
        return f"{iface} is not a CAN interface"
    if not int((sysfs / "flags").read_text(), 16) & IFF_UP:
        return f"{iface} is down"
    return None


@pytest.fixture(scope="session")
def ddct_bin(pytestconfig) -> Path:
    from .daemons import BenchError, find_ddct

    try:
        return find_ddct(pytestconfig.getoption("ddct_bin"), given_as="--ddct-bin PATH")
    except BenchError as e:
        why = str(e)
    pytest.fail(why, pytrace=False)  # outside the except: no chained BenchError in the report


@pytest.fixture(scope="session")
def ddct_iface(pytestconfig) -> str:
    iface = pytestconfig.getoption("ddct_iface") or os.environ.get("DDCT_IFACE") or "vcan0"
    why = interface_problem(iface)
    if why:
        pytest.fail(f"{why} (a bench needs an up CAN interface, e.g. vcan0 inside scripts/vcan-run)", pytrace=False)
    return iface


@pytest.fixture
def ddct_bus(ddct_iface):
    import can

    bus = can.Bus(interface="socketcan", channel=ddct_iface, receive_own_messages=False)
    try:
        yield bus
    finally:
        bus.shutdown()


@pytest.fixture
def ddct_monitor(request, ddct_bus):
    from .monitor import Monitor

    mark = request.node.get_closest_marker("ddct_monitor")
    messages = mark.kwargs.get("messages") if mark else None
    with Monitor(ddct_bus, messages) as mon:
        yield mon


@pytest.fixture
def ddct_driver(ddct_bus):
    from .driver import Driver

    with Driver(ddct_bus) as driver:
        yield driver


@pytest.fixture
def ddct_bench(pytestconfig, ddct_bin, ddct_iface, ddct_monitor, ddct_driver, tmp_path):
    from .daemons import Bench

    cfg = pytestconfig.getoption("ddct_tcu_config")  # None: the binary's built-in calibration
    with Bench(ddct_iface, ddct=ddct_bin, tcu_config=cfg, workdir=tmp_path / "bench") as bench:
        yield bench
